"""``PostFX``: the whole look, ``AutoExposure -> Bloom -> ColorGrade -> PrimaryGrade -> ToneMap -> Dither -> Display``,
built from arguments or a config.

Each stage is given as a module, a dict of its constructor arguments, or ``None``. Only the stages a
scene needs are built ("model only what a scene requires"): a grade or primary grade whose controls are
all identity, a bloom of intensity 0 (or ``max_iterations`` 0) and a dither of amplitude 0 are dropped, so they cost nothing in PyTorch and
add no ONNX nodes. Tone mapping is never dropped when given (even ``"none"`` clips to [0, 1]).

A config is a dict (or a JSON file) with the keys ``exposure``, ``bloom``, ``grade``, ``primary``,
``tonemap``, ``dither`` and ``display`` (the last three optional stages are off unless given; without
``display`` the look returns display-linear light, with it the display's signal, see
:class:`~torchgrade.display.Display`);
each holds the arguments of its stage (``tonemap`` may also be just a mode name)::

    {"bloom": {"intensity": 0.8, "threshold": 1.2},
     "grade": {"aces": true, "contrast": 20, "saturation": 10},
     "tonemap": {"mode": "aces"}}

Unknown stages and keys, unknown modes, values of the wrong JSON type and out-of-range values raise
``ValueError`` naming the key (``"unknown key 'grade.brightness'"``, ``"grade.contrast must lie in
[-100.0, 100.0], got 150"``). A list where a control takes one number (or one colour, one matrix) is
per-sample, and becomes the tensor :meth:`PostFX.to_config` wrote it from (:mod:`torchgrade.config`).

:meth:`PostFX.to_lut` bakes grade and tone mapping into one :class:`~torchgrade.lut.LUT3D` while
exposure, bloom and dither (which depend on neighbouring pixels, the whole frame or the pixel's position)
stay live.
"""

from __future__ import annotations

import copy
import inspect
from pathlib import Path
from typing import Optional

import torch
from torch import nn

from .bloom import Bloom
from .config import load_config
from .display import Display, display_settings
from .dither import Dither
from .exposure import AutoExposure
from .grade import ColorGrade
from .lut import INTERPOLATIONS, LUT3D, ErrorReport, bake_lut
from .primary import PrimaryGrade
from .tonemap import ToneMap

__all__ = ["PostFX", "STAGES", "SAFE_GLOBALS", "stage_keys", "build_stage", "is_identity_stage"]

STAGES = {"exposure": AutoExposure, "bloom": Bloom, "grade": ColorGrade, "primary": PrimaryGrade, "tonemap": ToneMap, "dither": Dither,
          "display": Display}
"""The configurable stages, in the order they run, and their classes."""


def stage_keys(stage: str) -> tuple:
    """The argument names a stage's config accepts: its constructor's signature (built from its controls).

    Examples:
        >>> stage_keys("dither")
        ('amplitude', 'seed', 'size')
        >>> stage_keys("primary")[:3]
        ('style', 'offset', 'exposure')
    """
    return tuple(inspect.signature(STAGES[stage]).parameters)


def build_stage(stage: str, spec) -> Optional[nn.Module]:
    """A stage module from a module, a dict of arguments (``tonemap`` also a mode name) or ``None``.

    Raises ``ValueError`` naming ``stage.key`` for unknown keys and for values the stage rejects.

    Examples:
        >>> build_stage("tonemap", "aces")
        ToneMap(mode='aces')
        >>> build_stage("grade", {"contrast": 150})
        Traceback (most recent call last):
        ...
        ValueError: grade.contrast must lie in [-100.0, 100.0], got 150.0
    """
    if spec is None or isinstance(spec, nn.Module):
        return spec
    if stage == "tonemap" and isinstance(spec, str):
        spec = {"mode": spec}
    if not isinstance(spec, dict):
        raise ValueError(f"{stage} must be a module, a dict of its arguments or None, got {type(spec).__name__}")
    known = stage_keys(stage)
    for key in spec:
        if key not in known:
            raise ValueError(f"unknown key '{stage}.{key}'; {stage} takes {', '.join(known)}")
    try:
        return STAGES[stage].from_config(spec)
    except (ValueError, TypeError) as error:
        raise ValueError(_qualified(stage, str(error), spec)) from None


def _qualified(stage: str, message: str, spec: dict) -> str:
    """Prefix a stage's error with ``stage.`` when it starts with one of the given keys, else ``stage: ``."""
    named = any(message.startswith(f"{key} ") for key in spec)
    return f"{stage}.{message}" if named else f"{stage}: {message}"


def is_identity_stage(module: nn.Module) -> bool:
    """True for a stage that cannot change any image, as the stage itself says (``is_identity``).

    Examples:
        >>> is_identity_stage(ColorGrade()), is_identity_stage(Dither(amplitude=0.0)), is_identity_stage(AutoExposure())
        (True, True, False)
    """
    return bool(getattr(module, "is_identity", False))


class PostFX(nn.Module):
    """A look: ``PostFX(exposure=None, bloom=None, grade=None, tonemap=None, primary=None, dither=None, display=None)``;
    see the module docstring.

    ``lut`` (a :class:`~torchgrade.lut.LUT3D`, applied with ``interpolation``) replaces ``grade``,
    ``primary`` and ``tonemap``; :meth:`to_lut` builds such a look. ``forward(image, dt=None)`` runs the stages in
    order; ``dt`` (seconds since the previous frame) is passed to the exposure stage, which keeps the
    adapted luminance between calls (see :class:`~torchgrade.AutoExposure`).

    Examples:
        >>> look = PostFX(grade={"contrast": 20, "saturation": 0.0}, bloom={"intensity": 0.0}, tonemap="aces")
        >>> list(look.stages())  # the identity bloom is not built
        ['grade', 'tonemap']
        >>> look.to_config()
        {'grade': {'contrast': 20}, 'tonemap': {'mode': 'aces'}}
    """

    def __init__(self, exposure=None, bloom=None, grade=None, tonemap=None, lut: Optional[LUT3D] = None,
                 interpolation: str = "tetrahedral", primary=None, dither=None, display=None):
        super().__init__()
        if lut is not None and (grade is not None or primary is not None or tonemap is not None):
            raise ValueError("a look takes either lut or grade/primary/tonemap, not both")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
        given = {"exposure": exposure, "bloom": bloom, "grade": grade, "primary": primary, "tonemap": tonemap, "dither": dither,
                 "display": display}
        for stage, spec in given.items():
            module = build_stage(stage, display_settings(spec, self.tonemap) if stage == "display" else spec)
            setattr(self, stage, None if module is None or is_identity_stage(module) else module)
        self.lut = lut
        self.interpolation = interpolation

    @classmethod
    def from_config(cls, config) -> "PostFX":
        """Build a look from a config dict or the path of a JSON file holding one.

        A file is read within bounds (see :func:`~torchgrade.config.load_config`); JSON lists where the
        stage keeps per-sample tensors come back as tensors, so ``to_config`` -> JSON -> ``from_config``
        rebuilds a per-sample look.

        Examples:
            >>> import json
            >>> look = PostFX(grade=ColorGrade(contrast=torch.tensor([10.0, 20.0])))
            >>> PostFX.from_config(json.loads(json.dumps(look.to_config()))).grade.contrast
            tensor([10., 20.])
        """
        if isinstance(config, (str, Path)):
            config = load_config(config)
        if not isinstance(config, dict):
            raise ValueError(f"a look config must be a dict, got {type(config).__name__}")
        for key in config:
            if key not in STAGES:
                raise ValueError(f"unknown key '{key}'; a look config has {', '.join(STAGES)}")
        return cls(**config)

    def to_config(self) -> dict:
        """The built stages' arguments as plain values (JSON-ready); ``PostFX.from_config`` inverts it."""
        if self.lut is not None:
            raise ValueError("a look baked to a LUT has no config; save the LUT with torchgrade.io.write_cube")
        config = {}
        for stage, module in self.stages().items():
            config[stage] = module.to_config()
        return config

    def get_extra_state(self) -> dict:
        """What ``state_dict()`` carries beside the tensors: each stage's config and which tensors are learnable.

        Plain values only, so ``torch.load(path, weights_only=True)`` reads it back and
        ``PostFX().load_state_dict(state)`` rebuilds the look (a look baked to a LUT loads into a look
        built with a LUT of the same size).
        """
        return {
            "stages": {name: module.to_config() for name, module in self.stages().items() if name != "lut"},
            "parameters": sorted(name for name, _ in self.named_parameters()),
            "interpolation": self.interpolation,
        }

    def set_extra_state(self, state: dict) -> None:
        self.interpolation = _checked_extra_state(state)["interpolation"]

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
        start = f"{prefix}{stage}."
        for key, value in state_dict.items():
            name = key[len(start):]
            if not key.startswith(start) or "." in name:
                continue  # nested modules are built by the stage itself
            value = nn.Parameter(value.clone()) if f"{stage}.{name}" in extra["parameters"] else value.clone()
            if name in getattr(module, "_control_names", ()):
                module.set_param(name, value)
            else:
                setattr(module, name, value)
        return module

    def stages(self) -> dict:
        """The built stages by name, in the order they run (``"lut"`` for a baked look)."""
        names = ("exposure", "bloom", "grade", "primary", "tonemap", "lut", "dither", "display")
        return {name: getattr(self, name) for name in names if getattr(self, name) is not None}

    def forward(self, image: torch.Tensor, dt=None) -> torch.Tensor:
        if self.exposure is not None:
            image = self.exposure(image, dt)
        return self.finish(image)

    def finish(self, image: torch.Tensor) -> torch.Tensor:
        """The stages after exposure: bloom, then grade, primary grade and tone mapping (or the baked LUT), then dither and display encoding."""
        if self.bloom is not None:
            image = self.bloom(image)
        if self.lut is not None:
            image = self.lut(image, self.interpolation)
        for stage in (self.grade, self.primary, self.tonemap):
            if stage is not None:
                image = stage(image)
        image = image if self.dither is None else self.dither(image)
        return image if self.display is None else self.display(image)

    def frame(self, image: torch.Tensor, adapted: torch.Tensor, dt) -> tuple:
        """The look without state, for serving: ``(image, adapted, dt) -> (output, new adapted)``.

        Needs an exposure stage; see :meth:`AutoExposure.frame` for ``adapted``.
        """
        if self.exposure is None:
            raise ValueError("frame() needs an exposure stage; call the look directly")
        exposed, adapted = self.exposure.frame(image, adapted, dt)
        return self.finish(exposed), adapted

    def per_pixel_input(self, image: torch.Tensor) -> torch.Tensor:
        """One frame as grade, primary grade and tone mapping (or a baked LUT) receive it: exposed as the
        first frame of a sequence (the adaptation state is left alone), then bloomed. What
        ``bake_lut(..., scene=)`` should see when the look's per-pixel stages are baked."""
        if self.exposure is not None:
            image, _ = self.exposure.frame(image, None, 0.0)
        return image if self.bloom is None else self.bloom(image)

    def per_pixel_stages(self) -> nn.Sequential:
        """Grade, primary grade and tone mapping (those built) as one transform: what a LUT can hold.

        Raises ``ValueError`` when the look has none of them.
        """
        transform = nn.Sequential(*(m for m in (self.grade, self.primary, self.tonemap) if m is not None))
        if len(transform) == 0:
            raise ValueError("nothing to bake: the look has neither a grade nor a tone mapper")
        return transform

    def to_lut(self, size: int = 33, interpolation: Optional[str] = None, output_encoding: str = "linear",
               entries: str = "sampled") -> "PostFX":
        """An equivalent look with grade, primary grade and tone mapping baked into a ``size``³ ``"logc_hdr"`` LUT.

        Exposure, bloom and dither stay live (copied, so the new look keeps its own adaptation state). The
        LUT's lattice is LogC up to linear 58.86, then a compressed tail up to 65504
        (:class:`~torchgrade.lut.LogCHDRShaper`), so no channel is clamped; a tone-mapped look clamps its
        output to [0, 1] after the lookup.
        ``output_encoding`` and ``entries`` (``"fitted"``: :func:`~torchgrade.lut.fit_entries`) are passed to
        :func:`~torchgrade.bake_lut`; the new LUT keeps the encoding and the
        bake's error report (``look.to_lut().lut.error_report``; a bake over 1 code warns).
        """
        transform = self.per_pixel_stages()
        lut = bake_lut(transform, size=size, shaper="logc_hdr", output_encoding=output_encoding, entries=entries)
        report = lut.error_report
        lut = LUT3D(lut.table.detach().float(), shaper=lut.shaper, domain=(lut.domain_min, lut.domain_max),
                    output_range=lut.output_range, output_encoding=lut.output_encoding)
        lut.error_report = report  # measured on the float64 table these entries are rounded from
        return PostFX(
            exposure=copy.deepcopy(self.exposure),
            bloom=copy.deepcopy(self.bloom),
            dither=copy.deepcopy(self.dither),
            display=copy.deepcopy(self.display),
            lut=lut,
            interpolation=interpolation or self.interpolation,
        )

    def extra_repr(self) -> str:
        return f"interpolation={self.interpolation!r}" if self.lut is not None else ""


def _checked_extra_state(extra) -> dict:
    """A saved look's extra state (:meth:`PostFX.get_extra_state`), or ``ValueError`` saying what in it is malformed:
    a state dict is untrusted, and a tampered one gave bare ``KeyError``, ``TypeError`` and ``AttributeError``.

    Examples:
        >>> _checked_extra_state({"stages": [], "parameters": [], "interpolation": "tetrahedral"})
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
    if extra.get("interpolation") not in INTERPOLATIONS:
        raise malformed(f"interpolation must be one of {INTERPOLATIONS}, got {extra.get('interpolation')!r}")
    return extra


SAFE_GLOBALS = (PostFX, LUT3D, ErrorReport, *STAGES.values())
"""The classes a saved look is made of. Registered with ``torch.serialization.add_safe_globals`` when
torchgrade is imported, so ``torch.load(path, weights_only=True)`` reads back a ``torch.save(look)``."""

torch.serialization.add_safe_globals(list(SAFE_GLOBALS))
