"""Random post-processing for training: ``RandomPostFX``, a per-sample random grade of a batch.

Follows kornia.augmentation's conventions: ``p`` (probability that a sample is changed),
``same_on_batch`` (one draw for the whole batch), ``keepdim``, and the sampled parameters kept in
``last_params`` and accepted back by ``forward(x, params=...)`` to replay the exact look, for
example on a label image. Unlike kornia, scene-referred values are never clamped.

**Ranges.** Every continuous control takes ``None`` (off) or a ``(min, max)`` range, sampled
uniformly per sample, in the units of :class:`torchgrade.ColorGrade` and :class:`torchgrade.Bloom`.
Everything is off by default, as in kornia's ``ColorJiggle``; a range ``(v, v)`` at the control's
identity is off too. Controls that are off are not computed; with every control off the layer
returns its input.

**Order**, that of the look's slots (:data:`torchgrade.look.slots.SLOTS`): (sRGB decode) -> bloom -> grade ->
tone mapper -> look LUT -> (sRGB encode).

**Tone mapping** is off by default (``tonemap=None``): the output of an HDR input stays
scene-referred linear, ready for the next augmentation or for the network. ``tonemap`` may name
one mode of :data:`torchgrade.TONEMAP_MODES` or a sequence of them, one chosen uniformly per
sample (:func:`~torchgrade.augment.per_sample.tonemap_per_sample`: each mode maps the batch, and each sample takes
its own).

**A look LUT** (``look_lut``: a :class:`~torchgrade.LookLUT`, a ``.cube``/CLF path, a
:class:`~torchgrade.LUT3D` or a table) is applied after the tone mapper, on display-referred values
(so it needs ``tonemap`` or ``input_space="srgb"``), with a contribution drawn per sample from
``look_lut_contribution`` (a ``(min, max)`` range in [0, 1]; the stage's own contribution when None).

**sRGB inputs** (``input_space="srgb"``) are display-referred images in [0, 1]: they are decoded
to linear, graded, encoded again and clamped to [0, 1], the display range they came from. They
are not tone mapped unless ``tonemap`` is given (then the decoded values are treated as
scene-referred linear, for example after a positive exposure).

**Skipped samples** (probability ``1 - p``) keep their input where the random controls act (bloom and
grade, blended back with ``torch.where``, so one graph serves the whole batch) and get a look LUT
contribution of 0, but the output transform, the tone mapper, applies to every sample: a batch never
mixes scene-referred and display-referred values. Without a tone mapper or look LUT a skipped sample's
output equals its input exactly. ``p = 0`` skips the random controls without computing them.

**Precision.** float16 and bfloat16 inputs are computed in float32 and returned in their own dtype.
"""

from __future__ import annotations

import inspect
import numbers
import threading

import torch
from kornia.augmentation import IntensityAugmentationBase2D
from torch import nn

from ..base.images import check_image, full_precision, to_input_dtype, working_dtype
from ..base.planes import joined
from ..bloom import BLOOM_MODES, bloom_settings, bloom_with_settings
from ..color import linear_to_srgb, srgb_to_linear
from ..grading.grade import color_grade_planes
from ..grading.layer import ColorGrade
from ..look.slots import SLOTS
from ..output.layer import LookLUT
from ..output.look_lut import look_lut
from ..runtime import DeferredCheck
from ..runtime.strips import pixelwise
from .inputs import check_srgb_peak, look_stage
from .per_sample import tonemap_per_sample
from .ranges import (
    BLOOM_CONTROLS,
    COLOUR_CONTROLS,
    GRADE_CONTROLS,
    INPUT_SPACES,
    checked_range,
    checked_tonemap,
    grade_identity,
    is_identity_range,
)
from .saved import LOADED_NAME

__all__ = ["RandomPostFX", "tonemap_per_sample", "GRADE_CONTROLS", "BLOOM_CONTROLS", "COLOUR_CONTROLS", "INPUT_SPACES"]

_RANDOM_SLOTS = ("bloom", "grade")
"""The slots whose controls are drawn and which a skipped sample passes through unchanged."""


class RandomPostFX(IntensityAugmentationBase2D):
    """Random per-sample post-processing of a batch ``(B, 3, H, W)``, one image ``(3, H, W)`` or clips ``(B, T, 3, H, W)``.

    A kornia intensity augmentation: inside ``kornia.augmentation.AugmentationSequential`` its draw is
    recorded and replayed like ``ColorJiggle``'s, ``inverse()`` leaves it out (it moves no pixel) and
    masks, boxes and keypoints pass through untouched.

    Args:
        post_exposure: ``(min, max)`` range in :class:`torchgrade.ColorGrade`'s units (stops), a magnitude
            ``x`` meaning ``(-x, x)`` as in kornia, or None.
        temperature: the same, in ``ColorGrade``'s units (-100..100).
        tint: the same, in ``ColorGrade``'s units (-100..100).
        contrast: the same, in ``ColorGrade``'s units (-100..100).
        split_balance: the same, in ``ColorGrade``'s units (-100..100); needs ``split_shadows`` or
            ``split_highlights``.
        hue_shift: the same, in degrees.
        saturation: the same, in ``ColorGrade``'s units (-100..100).
        split_shadows: ``(min, max)`` range of each gamma-space channel of the shadows' split-toning colour,
            inside [0, 1] (0.5 is neutral; a magnitude ``x`` is ``0.5 ± x``), or None.
        split_highlights: the same for the highlights' split-toning colour.
        bloom_threshold: ``(min, max)`` range of :func:`torchgrade.bloom.bloom`'s ``threshold`` (in gamma space),
            or None. Bloom runs when any bloom range is given (unless ``bloom_intensity=(0, 0)``); the others
            keep ``Bloom``'s defaults.
        bloom_intensity: the same for ``intensity``.
        bloom_scatter: the same for ``scatter``; needs ``bloom_mode="scattering"``.
        bloom_mode: ``"additive"`` or ``"scattering"``.
        tonemap: None (no tone mapping), a mode of :data:`torchgrade.TONEMAP_MODES`, or a sequence of
            modes chosen uniformly per sample; applied to every sample, skipped ones included.
        look_lut: None, or a creative LUT after the tone mapper (see the module docstring).
        look_lut_contribution: ``(min, max)`` range of the look LUT's contribution inside [0, 1], or None.
        aces: grade in ACEScc/ACEScg as :class:`torchgrade.ColorGrade` does.
        input_space: ``"linear"`` (scene-referred HDR) or ``"srgb"`` (sRGB-encoded LDR in [0, 1]; 0..255
            floats raise ``ValueError`` rather than being clamped).
        p: probability that a sample's random controls act; the others keep their input up to the output transform.
        same_on_batch: one draw for the whole batch (kornia's meaning, ``p`` included).
        keepdim: return a single ``(3, H, W)`` image as ``(3, H, W)`` rather than ``(1, 3, H, W)``.
        same_on_frame: for clips ``(B, T, 3, H, W)``, one look per clip (kornia ``VideoSequential``'s
            default) rather than one per frame; parameters then hold ``B`` rows, else ``B * T``.

    ``forward(input, params=None, *, generator=None)``: parameters are drawn from ``generator`` (a
    ``torch.Generator``; the global generator when None), or taken from ``params`` to replay a
    previous draw. The parameters used are kept in ``last_params`` (see :meth:`sample_params`), one
    copy per thread, so threads sharing the layer each read back their own draw; to pass a draw
    along explicitly, draw it with :meth:`sample_params` and give it as ``params``.

    Examples:
        >>> augment = RandomPostFX(contrast=(-30, 30), saturation=20, tonemap="neutral")
        >>> images = torch.rand(4, 3, 8, 8) * 4
        >>> out = augment(images, generator=torch.Generator().manual_seed(0))
        >>> sorted(augment.last_params)
        ['batch_prob', 'contrast', 'saturation', 'tonemap']
        >>> torch.equal(augment(images, params=augment.last_params), out)  # replayed exactly
        True
        >>> RandomPostFX.from_config(augment.to_config()).ranges == augment.ranges
        True
    """

    def __init__(
        self,
        post_exposure=None,
        temperature=None,
        tint=None,
        contrast=None,
        split_shadows=None,
        split_highlights=None,
        split_balance=None,
        hue_shift=None,
        saturation=None,
        bloom_threshold=None,
        bloom_intensity=None,
        bloom_scatter=None,
        bloom_mode: str = "additive",
        tonemap=None,
        look_lut=None,
        look_lut_contribution=None,
        aces: bool = False,
        input_space: str = "linear",
        p: float = 1.0,
        same_on_batch: bool = False,
        keepdim: bool = False,
        same_on_frame: bool = True,
    ):
        given = dict(locals())  # the range arguments, by name
        super().__init__(p=p, same_on_batch=bool(same_on_batch), keepdim=bool(keepdim))
        grade_ranges = {name: checked_range(name, given[name], ColorGrade.controls[name].range, grade_identity(name))
                        for name in GRADE_CONTROLS}
        self.grade_ranges = {name: r for name, r in grade_ranges.items() if r is not None and not is_identity_range(name, r)}
        bloom_ranges = {name: checked_range(name, given[name], allowed) for name, (_, allowed) in BLOOM_CONTROLS.items()}
        self.bloom_ranges = {name: r for name, r in bloom_ranges.items() if r is not None}
        if self.bloom_ranges.get("bloom_intensity") == (0.0, 0.0):
            self.bloom_ranges = {}
        self.bloom_mode = bloom_mode
        self.tonemap = checked_tonemap(tonemap)
        self.look_lut = look_stage(look_lut)
        self.look_ranges = self._look_ranges(look_lut_contribution)
        self.aces = bool(aces)
        self.input_space = input_space
        self.same_on_frame = bool(same_on_frame)
        self._check_settings()
        self._local = threading.local()
        self._range_check = DeferredCheck()  # made here, so that no graph a compiler records makes one

    def _look_ranges(self, contribution) -> dict:
        """The look LUT's contribution range (its own contribution when None), or nothing without a look LUT."""
        if self.look_lut is None:
            if contribution is not None:
                raise ValueError("look_lut_contribution needs a look_lut")
            return {}
        if contribution is None:
            own = self.look_lut.contribution
            if isinstance(own, torch.Tensor):
                raise ValueError("give look_lut_contribution as a range: the look LUT's contribution is a tensor")
            contribution = (own, own)
        return {"look_lut_contribution": checked_range("look_lut_contribution", contribution, LookLUT.controls["contribution"].range)}

    def _check_settings(self) -> None:
        if self.bloom_mode not in BLOOM_MODES:
            raise ValueError(f"bloom_mode must be one of {BLOOM_MODES}, got {self.bloom_mode!r}")
        if "bloom_scatter" in self.bloom_ranges and self.bloom_mode != "scattering":
            raise ValueError('bloom_scatter only acts in scattering mode: pass bloom_mode="scattering"')
        if "split_balance" in self.grade_ranges and not set(COLOUR_CONTROLS) & set(self.grade_ranges):
            raise ValueError("split_balance changes nothing without split_shadows or split_highlights")
        if self.input_space not in INPUT_SPACES:
            raise ValueError(f"input_space must be one of {INPUT_SPACES}, got {self.input_space!r}")
        if self.look_lut is not None and not self.tonemap and self.input_space != "srgb":
            raise ValueError('look_lut takes display-referred values: give a tonemap, or input_space="srgb" images')
        if isinstance(self.p, bool) or not isinstance(self.p, numbers.Real) or not 0.0 <= self.p <= 1.0:
            raise ValueError(f"p must be a probability in [0, 1], got {self.p!r}")

    @property
    def ranges(self) -> dict:
        """The ranges sampled, by control name, in sampling order."""
        return {**self.bloom_ranges, **self.grade_ranges, **self.look_ranges}

    @property
    def is_identity(self) -> bool:
        """True when no control, bloom, tone mapper or look LUT is on: the layer then returns its input."""
        return not (self.ranges or self.tonemap)

    def slots(self) -> tuple:
        """The look's slots (:data:`~torchgrade.look.slots.SLOTS`) this layer fills, in their order, with whether a
        skipped sample (``batch_prob`` False) leaves the slot's input unchanged (the random controls) or not (the
        tone mapper, the output transform; a look LUT's contribution is 0 for it)."""
        filled = {"bloom": bool(self.bloom_ranges), "grade": bool(self.grade_ranges), "tonemap": bool(self.tonemap),
                  "look_lut": self.look_lut is not None}
        return tuple(slot.name for slot in SLOTS if filled.get(slot.name))

    def _widths(self) -> list:
        return [3 if name in COLOUR_CONTROLS else 1 for name in self.ranges]

    def sample_params(self, batch_size: int, generator: torch.Generator | None = None, device=None) -> dict:
        """Draw the parameters of a batch in one call to ``torch.rand`` (kornia's ``forward_parameters``).

        Returns a dict of tensors on ``device``: ``"batch_prob"`` (B,) bool, which samples are changed
        (kornia's name); one entry per sampled control, (B,) or (B, 3) for colours, in its units;
        ``"tonemap"`` (B,) int64, the index of each sample's mode in ``self.tonemap``, when tone mapping.
        Draws happen on the generator's device, or without one on ``device`` from torch's default generator there
        (nothing is copied to a GPU per batch); a CPU generator gives the same draws, and looks, on every device.
        """
        rows = 1 if self.same_on_batch else batch_size
        widths = self._widths()
        columns = 1 + sum(widths) + (1 if self.tonemap else 0)
        draw_device = generator.device if generator is not None else torch.device(device or "cpu")
        uniform = torch.rand(rows, columns, generator=generator, device=draw_device)
        uniform = uniform.to(device or draw_device).expand(batch_size, -1).contiguous()
        params = {"batch_prob": uniform[:, 0] < self.p}
        controls = uniform[:, 1 : 1 + sum(widths)].split(widths, dim=1)
        for (name, (low, high)), u in zip(self.ranges.items(), controls):
            value = (low + (high - low) * u).clamp(low, high)  # the clamp only absorbs rounding
            params[name] = value if name in COLOUR_CONTROLS else value.squeeze(1)
        if self.tonemap:
            params["tonemap"] = (uniform[:, -1] * len(self.tonemap)).long().clamp_max(len(self.tonemap) - 1)
        return params

    def forward_parameters(self, batch_shape) -> dict:
        """kornia's hook: the draw for a batch of ``batch_shape[0]`` images, from the global generator, with
        the input shape kornia's mask and box handlers read."""
        return {**self.sample_params(batch_shape[0]), "forward_input_shape": torch.tensor(tuple(batch_shape))}

    @property
    def last_params(self) -> dict | None:
        """The parameters of this thread's last call (None before it has one)."""
        return getattr(self._local, "params", None)

    def _param_names(self) -> set:
        return {"batch_prob", *self.ranges, *(("tonemap",) if self.tonemap else ())}

    def _checked_params(self, params: dict, rows: int, device) -> dict:
        """Replayed parameters, checked against this layer's controls and the batch, on the images' device."""
        expected = self._param_names()
        if isinstance(params, dict):
            params = {name: value for name, value in params.items() if name != "forward_input_shape"}  # kornia's, unused
        if not isinstance(params, dict) or set(params) != expected:
            given = sorted(params) if isinstance(params, dict) else type(params).__name__
            raise ValueError(f"params must be a dict with keys {sorted(expected)} (see last_params), got {given}")
        for name, value in params.items():
            if not isinstance(value, torch.Tensor) or value.dim() == 0 or value.shape[0] != rows:
                raise ValueError(f"params[{name!r}] must be a tensor with {rows} per-sample values, got {value!r}")
        return {name: value.to(device) for name, value in params.items()}

    def transform(self, images: torch.Tensor, params: dict, applied: torch.Tensor | None = None, planes: bool = False) -> torch.Tensor:
        """Apply ``params`` to ``images`` (B, 3, H, W), slot by slot in the look's order (:meth:`slots`); with
        ``applied`` ((B, 1, 1, 1) bool), only its samples get the random controls; ``planes``: the grade computes on
        the image's planes (:func:`~torchgrade.grading.grade.color_grade_planes`)."""
        x = working_dtype(images)
        if self.input_space == "srgb":
            x = srgb_to_linear(x)
        held = None  # the input of the random controls, kept for the skipped samples
        for slot in self.slots():
            random = slot in _RANDOM_SLOTS
            if random and held is None and applied is not None:
                held = x
            if not random and held is not None and applied is not None:  # held only where some samples are skipped
                x, held = torch.where(applied, joined(x), joined(held)), None
            x = self._grade(x, params, planes) if slot == "grade" else getattr(self, f"_{slot}")(joined(x), params, applied)

        def finished(graded, source):  # encoded, in the input's dtype; only random controls: skipped samples exact
            graded = to_input_dtype(linear_to_srgb(graded).clamp(0.0, 1.0) if self.input_space == "srgb" else graded, source)
            return graded if held is None else torch.where(applied, graded, source)

        if isinstance(x, tuple):  # the grade's planes: finished plane by plane into the output's stack
            return joined(tuple(finished(*planes) for planes in zip(x, images.split(1, dim=-3))))
        return finished(x, images)

    def _bloom(self, x: torch.Tensor, params: dict, applied) -> torch.Tensor:
        controls = {BLOOM_CONTROLS[name][0]: params[name] for name in self.bloom_ranges}
        return bloom_with_settings(x, bloom_settings({"mode": self.bloom_mode, **controls}))  # drawn inside their ranges

    def _grade(self, x: torch.Tensor, params: dict, planes: bool):
        """The graded image, or its planes (:func:`~torchgrade.grading.grade.color_grade_planes`)."""
        return color_grade_planes(x, aces=self.aces, planes=planes, **{name: params[name] for name in self.grade_ranges})

    def _tonemap(self, x: torch.Tensor, params: dict, applied) -> torch.Tensor:
        return tonemap_per_sample(x, params["tonemap"], self.tonemap)

    def _look_lut(self, x: torch.Tensor, params: dict, applied) -> torch.Tensor:
        contribution = params["look_lut_contribution"]
        contribution = contribution if applied is None else contribution * applied.reshape(-1)
        assert self.look_lut is not None  # a look_lut slot runs only with one
        return look_lut(x, self.look_lut.lut, contribution, self.look_lut.encoding)

    def apply_transform(self, input: torch.Tensor, params: dict, flags: dict, transform=None) -> torch.Tensor:
        """kornia's hook: :meth:`transform`."""
        return self.transform(input, params)

    def _check_display_range(self, images: torch.Tensor) -> None:
        """Refuse 0..255 floats given as sRGB (kornia would clamp them to white). The batch's peak is read back
        without waiting for a GPU (:class:`~torchgrade.runtime.DeferredCheck`): there a batch out of range raises
        at a later call."""
        self._range_check({"peak": images.detach().amax()}, check_srgb_peak)

    def _graded(self, images: torch.Tensor, params: dict) -> torch.Tensor:
        """The batch graded by ``params``, with autocast off (:func:`~torchgrade.base.images.full_precision`): the
        stages' maths keeps float32 or better whatever autocast a training loop runs, as each stage's call does."""
        if self.is_identity or (self.p == 0 and not self.tonemap):
            return images
        if self.input_space == "srgb":
            self._check_display_range(images)
        applied = params["batch_prob"].bool().reshape(-1, 1, 1, 1)
        with full_precision():
            if "bloom" in self.slots():
                return self.transform(images, params, applied)
            return self._pixels(images, params, applied)

    @pixelwise(planes=True)
    def _pixels(self, images: torch.Tensor, params: dict, applied: torch.Tensor, *, planes: bool = False) -> torch.Tensor:
        """:meth:`transform` of a batch whose every slot is per-pixel (no bloom), as the runtime runs a per-pixel module
        (:func:`~torchgrade.runtime.strips.pixelwise`: strips of rows on the CPU, eager; planes where a compiler fuses)."""
        return self.transform(images, params, applied, planes)

    def forward(self, input: torch.Tensor, params: dict | None = None, *, generator: torch.Generator | None = None,
                **container_args) -> torch.Tensor:
        """Grade ``input`` with a new draw (or ``params``, second as in kornia's ``forward(input, params)``);
        ``container_args`` (``data_keys`` ...) are what kornia's containers pass along: an intensity layer needs none."""
        check_image(input)
        images, rows, frames = self._batch(input)
        if params is None:
            params = self.sample_params(rows, generator, images.device)
        else:
            params = self._checked_params(params, rows, images.device)
        self._local.params = params
        self._commit_state(params=params)
        per_image = params if rows == images.shape[0] else {k: v.repeat_interleave(frames, 0) for k, v in params.items()}
        out = self._graded(images, per_image)
        if input.dim() == 5 or (self.keepdim and input.dim() == 3):
            return out.reshape(input.shape)
        return out

    def _batch(self, x: torch.Tensor) -> tuple:
        """``x`` as a batch of images ``(N, 3, H, W)``, the number of draws it takes (one a clip when ``same_on_frame``)
        and the frames a draw serves."""
        if x.dim() not in (3, 4, 5):
            raise ValueError(f"RandomPostFX takes (3, H, W), (B, 3, H, W) or (B, T, 3, H, W) images, got shape {tuple(x.shape)}")
        images = x if x.dim() == 4 else x.reshape(-1, *x.shape[-3:])
        clips, frames = (x.shape[0], x.shape[1]) if x.dim() == 5 else (images.shape[0], 1)
        return images, clips if self.same_on_frame else images.shape[0], frames

    def compiled_arguments(self, x: torch.Tensor, params: dict | None = None, *, generator: torch.Generator | None = None,
                           **container_args) -> tuple:
        """The arguments of a compiled call (:func:`torchgrade.compile`): the draw made here, before the graph, from
        ``generator`` as an eager call makes it, and passed in as ``params`` (a generator cannot enter a compiled graph).

        Examples:
            >>> layer = RandomPostFX(contrast=(-20, 20))
            >>> args, kwargs = layer.compiled_arguments(torch.rand(2, 3, 4, 4), generator=torch.Generator().manual_seed(0))
            >>> sorted(kwargs["params"])
            ['batch_prob', 'contrast']
        """
        if params is None and isinstance(x, torch.Tensor):
            images, rows, _ = self._batch(x)
            params = self.sample_params(rows, generator, images.device)
        return (x,), {"params": params, **container_args}

    def to_config(self) -> dict:
        """The layer's arguments that differ from their defaults, as plain values (JSON-ready).

        ``RandomPostFX.from_config(layer.to_config())`` builds a layer that draws the same looks.
        """
        config: dict[str, object] = {name: list(pair) for name, pair in self.ranges.items()}
        look = None if self.look_lut is None else {k: v for k, v in self.look_lut.to_config().items() if k != "contribution"}
        settings = {"bloom_mode": self.bloom_mode if self.bloom_ranges else "additive",
                    "tonemap": list(self.tonemap) or None, "look_lut": look, "aces": self.aces, "input_space": self.input_space,
                    "p": self.p, "same_on_batch": self.same_on_batch, "keepdim": self.keepdim,
                    "same_on_frame": self.same_on_frame}
        defaults = inspect.signature(type(self)).parameters  # stated once, in the constructor
        config.update({name: value for name, value in settings.items() if value != defaults[name].default})
        return config

    @classmethod
    def from_config(cls, config: dict) -> "RandomPostFX":
        """Build the layer from a dict of its arguments (what :meth:`to_config` returns)."""
        if not isinstance(config, dict):
            raise ValueError(f"a RandomPostFX config must be a dict, got {type(config).__name__}")
        known = set(inspect.signature(cls).parameters)
        unknown = sorted(set(config) - known)
        if unknown:
            raise ValueError(f"unknown RandomPostFX argument(s) {unknown}; known: {', '.join(sorted(known))}")
        return cls(**config)

    def __getstate__(self) -> dict:
        state = dict(super().__getstate__())
        state.pop("_local", None)  # per-thread draws stay with their thread: a copy starts without one
        state.pop("_range_check", None)  # pending checks hold CUDA events
        return state

    def __setstate__(self, state: dict) -> None:
        super().__setstate__(state)
        self._local = threading.local()
        self._range_check = DeferredCheck()
        type(self).from_config(self.to_config())  # a saved layer is untrusted: its ranges are checked as construction checks them

    __repr__ = nn.Module.__repr__  # kornia's own repr lists only p and same_on_batch

    def extra_repr(self) -> str:
        settings = [f"{name}={r}" for name, r in self.ranges.items()]
        if self.bloom_ranges:
            settings.append(f"bloom_mode={self.bloom_mode!r}")
        if self.tonemap:
            settings.append(f"tonemap={self.tonemap}")
        if self.look_lut is not None:
            settings.append(f"look_lut=({self.look_lut.extra_repr()})")
        if self.aces:
            settings.append("aces=True")
        settings += [f"input_space={self.input_space!r}", f"p={self.p}", f"same_on_batch={self.same_on_batch}"]
        return ", ".join(settings)


torch.serialization.add_safe_globals([(RandomPostFX, LOADED_NAME)])  # a weights_only load fills one (augment_saved)
