r"""``PostFX``: the whole look, its stages in the order of :data:`SLOTS`, built from arguments or a config.

The look's slots, in the order they run (one declaration, :data:`SLOTS`, read by the constructor,
``forward``, the config, :meth:`PostFX.to_lut`, the ONNX export and :class:`~torchgrade.RandomPostFX`)::

    exposure -> bloom -> grade -> primary -> tonemap -> look_lut -> dither -> display
                         \______ a baked lut ______/

Each stage is given as a module, a dict of its constructor arguments, or ``None``. Only the stages a
scene needs are built ("model only what a scene requires"): a grade or primary grade whose controls are
all identity, a bloom of intensity 0 (or ``max_iterations`` 0), a look LUT of contribution 0 and a dither of
amplitude 0 are dropped, so they cost nothing in PyTorch and add no ONNX nodes. Tone mapping is never
dropped when given (even ``"none"`` clips to [0, 1]).

A config is a dict (or a JSON file) whose keys are the slots' names (all optional; without ``display``
the look returns display-linear light, with it the display's signal, see
:class:`~torchgrade.output.layer.Display`); each holds the arguments of its stage (``tonemap`` may also be
just a mode name, ``look_lut`` just the path of a ``.cube`` or CLF file)::

    {"bloom": {"intensity": 0.8, "threshold": 1.2},
     "grade": {"aces": true, "contrast": 20, "saturation": 10},
     "tonemap": {"mode": "aces"},
     "look_lut": {"lut": "show.cube", "contribution": 0.6}}

Unknown stages and keys, unknown modes, values of the wrong JSON type and out-of-range values raise
``ValueError`` naming the key (``"unknown key 'grade.brightness'"``, ``"grade.contrast must lie in
[-100.0, 100.0], got 150"``). A list where a control takes one number (or one colour, one matrix) is
per-sample, and becomes the tensor :meth:`PostFX.to_config` wrote it from (:mod:`torchgrade.base.config`).

:meth:`PostFX.to_lut` bakes the slots a LUT can hold (grade, primary grade and tone mapping) into one
:class:`~torchgrade.lut.LUT3D`, the look's ``lut`` slot, while the others (exposure, bloom, the look LUT,
dither, display) stay live.
"""

from __future__ import annotations

import contextlib
import copy
import inspect
from pathlib import Path
from typing import Optional

import torch
from torch import nn

from ..base.config import load_config
from ..base.images import with_alpha
from ..base.stage import Stage
from ..bloom import ConvolutionBloom
from ..exposure import AutoExposure
from ..lut import INTERPOLATIONS, LUT3D, ErrorReport
from ..lut.bake import bake_look
from .slots import SLOT, SLOTS, STAGES, build_stage, is_identity_stage

__all__ = ["PostFX", "SAFE_GLOBALS"]


def _constructor_signature() -> inspect.Signature:
    keyword = inspect.Parameter.KEYWORD_ONLY
    slots = [inspect.Parameter(slot.name, keyword, default=None) for slot in SLOTS]
    return inspect.Signature([*slots, inspect.Parameter("interpolation", keyword, default=None)])


class PostFX(nn.Module):
    """A look: ``PostFX(exposure=None, bloom=None, grade=None, primary=None, tonemap=None, lut=None, look_lut=None,
    dither=None, display=None)``, one keyword a slot of :data:`SLOTS`; see the module docstring.

    ``lut`` (a :class:`~torchgrade.lut.LUT3D`) stands for ``grade``, ``primary`` and ``tonemap``; :meth:`to_lut`
    builds such a look, and ``interpolation`` looks that LUT up another way than its own (the ``LUT3D``'s control). ``look_lut`` (a :class:`~torchgrade.LookLUT`, a
    ``.cube``/CLF path or a dict of its arguments) is a creative LUT on the display-referred image, so it needs a
    tone mapper (or a baked LUT that clamps to [0, 1]) before it. ``forward(image, dt=None)`` runs the stages in
    order; ``dt`` (seconds since the previous frame) is passed to the exposure stage, which keeps the adapted
    luminance between calls (see :class:`~torchgrade.AutoExposure`).

    Examples:
        >>> look = PostFX(grade={"contrast": 20, "saturation": 0.0}, bloom={"intensity": 0.0}, tonemap="aces")
        >>> list(look.stages())  # the identity bloom is not built
        ['grade', 'tonemap']
        >>> look.to_config()
        {'grade': {'contrast': 20}, 'tonemap': {'mode': 'aces'}}
    """

    exposure: Optional[AutoExposure]
    bloom: Optional[nn.Module]
    grade: Optional[nn.Module]
    primary: Optional[nn.Module]
    tonemap: Optional[nn.Module]
    lut: Optional[LUT3D]
    look_lut: Optional[nn.Module]
    dither: Optional[nn.Module]
    display: Optional[nn.Module]

    def __init__(self, **slots):
        super().__init__()
        interpolation = slots.pop("interpolation", None)
        unknown = sorted(set(slots) - set(SLOT))
        if unknown:
            raise TypeError(f"PostFX got unknown slot(s) {unknown}; its slots are {', '.join(SLOT)}")
        baked = [slot.name for slot in SLOTS if slot.bakes and slots.get(slot.name) is not None]
        if slots.get("lut") is not None and baked:
            raise ValueError(f"a look takes either lut or {'/'.join(s.name for s in SLOTS if s.bakes)}, not both (got {baked})")
        for slot in SLOTS:
            spec = slots.get(slot.name)
            if slot.baked:
                module = _baked_lut(spec, interpolation)
            else:
                module = build_stage(slot.name, slot.completed(spec, self) if slot.completed and spec is not None else spec)
            setattr(self, slot.name, None if module is None or is_identity_stage(module) else module)
        if interpolation is not None and self.lut is None:
            raise ValueError("interpolation sets a baked look's LUT: the look has no lut")
        self._check_look_lut_input()

    __signature__ = _constructor_signature()

    def _check_look_lut_input(self) -> None:
        """A look LUT takes display-referred light: refuse one with nothing before it that makes such light."""
        if self.look_lut is None:
            return
        ahead = self.lut if self.lut is not None else self.tonemap
        clamps = self.lut is not None and self.lut.output_range is not None and self.lut.output_range[1] <= 1.0
        if ahead is None or (self.lut is not None and not clamps):
            raise ValueError("look_lut takes display-referred light: give the look a tonemap (or a baked lut that "
                             "clamps to [0, 1]) before it")

    @classmethod
    def from_config(cls, config) -> "PostFX":
        """Build a look from a config dict or the path of a JSON file holding one.

        A file is read within bounds (see :func:`~torchgrade.base.config.load_config`), and a look LUT's relative path in
        it is taken from the file's folder; JSON lists where the stage keeps per-sample tensors come back as
        tensors, so ``to_config`` -> JSON -> ``from_config`` rebuilds a per-sample look.

        Examples:
            >>> import json
            >>> from torchgrade import ColorGrade
            >>> look = PostFX(grade=ColorGrade(contrast=torch.tensor([10.0, 20.0])))
            >>> PostFX.from_config(json.loads(json.dumps(look.to_config()))).grade.contrast
            tensor([10., 20.])
        """
        folder = None
        if isinstance(config, (str, Path)):
            folder = Path(config).parent
            config = load_config(config)
        if not isinstance(config, dict):
            raise ValueError(f"a look config must be a dict, got {type(config).__name__}")
        for key in config:
            if key not in STAGES:
                raise ValueError(f"unknown key '{key}'; a look config has {', '.join(STAGES)}")
        return cls(**_files_beside(config, folder))

    def to_config(self) -> dict:
        """The built stages' arguments as plain values (JSON-ready); ``PostFX.from_config`` inverts it."""
        if self.lut is not None:
            raise ValueError("a look baked to a LUT has no config; save the LUT with torchgrade.io.write_cube")
        return {name: module.to_config() for name, module in self.stages().items()}

    def get_extra_state(self) -> dict:
        """What ``state_dict()`` carries beside the tensors: each stage's config and which tensors are learnable.

        Plain values only, so ``torch.load(path, weights_only=True)`` reads it back and
        ``PostFX().load_state_dict(state)`` rebuilds the look (a look baked to a LUT loads into a look
        built with a LUT of the same size).
        """
        state = {
            "stages": {name: module.state_config() for name, module in self.stages().items() if not SLOT[name].baked},
            "parameters": sorted(name for name, _ in self.named_parameters()),
        }
        return state if self.lut is None else {**state, "interpolation": self.lut.interpolation}

    def set_extra_state(self, state: dict) -> None:
        interpolation = _checked_extra_state(state).get("interpolation")
        if interpolation is not None and self.lut is not None:
            self.lut.interpolation = interpolation

    def _load_from_state_dict(self, state_dict, prefix, *args) -> None:
        extra = state_dict.get(prefix + "_extra_state")
        if extra is not None and self.lut is None:
            _checked_extra_state(extra)
            for stage in STAGES:
                config = extra["stages"].get(stage)
                setattr(self, stage, None if config is None else self._saved_stage(stage, config, extra, state_dict, prefix))
        super()._load_from_state_dict(state_dict, prefix, *args)

    @staticmethod
    def _saved_stage(stage: str, config: dict, extra: dict, state_dict: dict, prefix: str) -> nn.Module:
        """A stage rebuilt from its saved config, its own tensors (learnable ones as parameters) at their saved shapes."""
        module = build_stage(stage, config)
        assert isinstance(module, Stage)  # built from a config: the slot's stage class
        start = f"{prefix}{stage}."
        for key, value in state_dict.items():
            name = key[len(start):]
            if not key.startswith(start) or "." in name:
                continue  # nested modules are built by the stage itself
            value = nn.Parameter(value.clone()) if f"{stage}.{name}" in extra["parameters"] else value.clone()
            if name in module._control_names:
                module.set_param(name, value)
            else:
                setattr(module, name, value)
        return module

    def stages(self) -> dict:
        """The built stages by name, in the order they run (:data:`SLOTS`)."""
        return {slot.name: getattr(self, slot.name) for slot in SLOTS if getattr(self, slot.name) is not None}

    def forward(self, image: torch.Tensor, dt=None) -> torch.Tensor:
        return with_alpha(self._graded, image, dt)  # an RGBA frame's alpha is split off once, not at every stage

    def _graded(self, image: torch.Tensor, dt) -> torch.Tensor:
        """The stages in order on the colour channels, ``dt`` to those that keep state between frames."""
        return _through(self.stages().items(), image, dt)

    def compiled_frame(self, image: torch.Tensor, dt=None):
        """Around a compiled frame (:func:`torchgrade.compile` enters it): the exposure stage's
        :meth:`~torchgrade.AutoExposure.compiled_frame`, so one graph serves the first frame and the next."""
        return self.exposure.compiled_frame(image, dt) if self.exposure is not None else contextlib.nullcontext()

    def finish(self, image: torch.Tensor) -> torch.Tensor:
        """The stages after exposure (those that keep no state between frames), in order."""
        return _through([(name, stage) for name, stage in self.stages().items() if not SLOT[name].timed], image, None)

    def frame(self, image: torch.Tensor, adapted: torch.Tensor, dt) -> tuple:
        """The look without state, for serving: ``(image, adapted, dt) -> (output, new adapted)``.

        Needs an exposure stage; see :meth:`AutoExposure.frame` for ``adapted``.
        """
        if self.exposure is None:
            raise ValueError("frame() needs an exposure stage; call the look directly")
        exposed, adapted = self.exposure.frame(image, adapted, dt)
        return self.finish(exposed), adapted

    def per_pixel_input(self, image: torch.Tensor) -> torch.Tensor:
        """One frame as the slots a LUT bakes receive it: through the stages before them, exposure as the first frame
        of a sequence (the adaptation state is left alone). What ``bake_lut(..., scene=)`` should see."""
        for slot in SLOTS:
            if slot.bakes or slot.baked:
                return image
            stage = getattr(self, slot.name)
            if stage is not None:
                image = stage.frame(image, None, 0.0)[0] if slot.timed else stage(image)
        return image

    def per_pixel_stages(self) -> nn.Sequential:
        """The slots a LUT can hold (grade, primary grade and tone mapping), those built, as one transform.

        Raises ``ValueError`` when the look has none of them.
        """
        transform = nn.Sequential(*(getattr(self, s.name) for s in SLOTS if s.bakes and getattr(self, s.name) is not None))
        if len(transform) == 0:
            raise ValueError("nothing to bake: the look has neither a grade nor a tone mapper")
        return transform

    def to_lut(self, size: Optional[int] = None, interpolation: Optional[str] = None, output_encoding: str = "linear",
               entries: str = "sampled", frames: Optional[torch.Tensor] = None) -> "PostFX":
        """An equivalent look with grade, primary grade and tone mapping baked into a LUT: the table
        ``tg.bake_lut(look, ...)`` bakes from the same arguments (:func:`~torchgrade.lut.bake.bake_look`), on the default
        lattice (``"logc_extended"`` at its default size, or ``size``³), its entries rounded to float32.

        The other slots stay live (copied, so the new look keeps its own adaptation state). The
        LUT's lattice is LogC up to linear 58.86, then a tail in stops up to 65504
        (:class:`~torchgrade.lut.shapers.LogCExtendedShaper`), so no channel is clamped; a tone-mapped look clamps its
        output to [0, 1] after the lookup. ``interpolation`` is the LUT's (tetrahedral by default).
        ``output_encoding`` and ``entries`` (``"fitted"``: :func:`~torchgrade.lut.fit_entries`) are passed to
        :func:`~torchgrade.bake_lut`; the new LUT keeps the encoding and the
        bake's error report (``look.to_lut().lut.error_report``; a bake over 1 code warns). With ``frames``
        (``(..., 3, H, W)`` scene-referred, as the look takes them) the report is measured on those frames as the LUT
        receives them (after the stages before it) rather than on the realistic colours.
        """
        lut = bake_look(self, size=size, output_encoding=output_encoding, entries=entries, frames=frames)
        report = lut.error_report
        lut = LUT3D(lut.table.detach().float(), shaper=lut.shaper, domain=(lut.domain_min, lut.domain_max),
                    output_range=lut.output_range, output_encoding=lut.output_encoding,
                    interpolation=interpolation or "tetrahedral")
        lut.error_report = report  # measured on the float64 table these entries are rounded from
        live = {s.name: copy.deepcopy(getattr(self, s.name)) for s in SLOTS if not (s.bakes or s.baked)}
        return PostFX(**live, lut=lut)


def _baked_lut(lut, interpolation: Optional[str]) -> Optional[LUT3D]:
    """The ``lut`` slot's LUT, looked up with ``interpolation`` when given (:meth:`LUT3D.looked_up_with`)."""
    if lut is None:
        return None
    if not isinstance(lut, LUT3D):
        raise ValueError(f"lut must be a LUT3D (a baked look; see PostFX.to_lut), got {type(lut).__name__}")
    return lut.looked_up_with(interpolation)


def _files_beside(config: dict, folder: Optional[Path]) -> dict:
    """``config`` with a look LUT's relative file path taken from ``folder`` (the config file's), when there is one."""
    spec = config.get("look_lut")
    path = spec.get("lut") if isinstance(spec, dict) else spec
    if folder is None or not isinstance(path, str) or Path(path).is_absolute():
        return config
    located = str(folder / path)
    return {**config, "look_lut": {**spec, "lut": located} if isinstance(spec, dict) else located}


def _checked_extra_state(extra) -> dict:
    """A saved look's extra state (:meth:`PostFX.get_extra_state`), or ``ValueError`` saying what in it is malformed:
    a state dict is untrusted, and a tampered one gave bare ``KeyError``, ``TypeError`` and ``AttributeError``.

    Examples:
        >>> _checked_extra_state({"stages": [], "parameters": []})
        Traceback (most recent call last):
        ...
        ValueError: a saved look's _extra_state is malformed: stages must map stage names to configs, got list
    """
    def malformed(what: str):
        return ValueError(f"a saved look's _extra_state is malformed: {what}")

    if not isinstance(extra, dict):
        raise malformed(f"it must be a dict, got {type(extra).__name__}")
    stages, parameters = extra.get("stages"), extra.get("parameters")
    if not isinstance(stages, dict):
        raise malformed(f"stages must map stage names to configs, got {type(stages).__name__}")
    for stage, config in stages.items():
        if stage not in STAGES or not isinstance(config, dict):
            raise malformed(f"stages holds {stage!r}: {type(config).__name__}; stages are {', '.join(STAGES)}, each a dict")
    if not isinstance(parameters, list) or not all(isinstance(name, str) for name in parameters):
        raise malformed("parameters must be a list of names")
    if extra.get("interpolation", "tetrahedral") not in INTERPOLATIONS:
        raise malformed(f"interpolation must be one of {INTERPOLATIONS}, got {extra.get('interpolation')!r}")
    return extra


SAFE_GLOBALS = (PostFX, LUT3D, ErrorReport, ConvolutionBloom, *STAGES.values())
"""The classes a saved look is made of. Registered with ``torch.serialization.add_safe_globals`` when
torchgrade is imported, so ``torch.load(path, weights_only=True)`` reads back a ``torch.save(look)``."""

torch.serialization.add_safe_globals(list(SAFE_GLOBALS))


def _through(stages, image: torch.Tensor, dt) -> torch.Tensor:
    """``image`` through ``(slot name, stage)`` pairs in order, ``dt`` to those that keep state between frames.

    A stage's output holds no NaN (``tests/library/test_extremes.py``), so a stage whose input another stage made is
    told so (``nan_free=True``, :attr:`~torchgrade.base.stage.Stage.takes_nan_free`) and skips its input's NaN pass, one
    frame pass each. A stage that hands its input back (an identity setting, a frame too small for a bloom level)
    makes nothing: its output is as trusted as its input was.
    """
    made = False
    for name, stage in stages:
        args = (dt,) if SLOT[name].timed else ()
        trusted = {"nan_free": True} if made and getattr(stage, "takes_nan_free", False) else {}
        out = stage(image, *args, **trusted)
        made = made or out is not image
        image = out
    return image
