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

**Order**, that of the library's pipeline: (sRGB decode) -> bloom -> grade -> tone mapper ->
(sRGB encode).

**Tone mapping** is off by default (``tonemap=None``): the output of an HDR input stays
scene-referred linear, ready for the next augmentation or for the network. ``tonemap`` may name
one mode of :data:`torchgrade.TONEMAP_MODES` or a sequence of them, one chosen uniformly per
sample. Each mode is evaluated once, on the samples that chose it (the batch is sorted by mode,
split, mapped and put back in order), so a batch costs one tone mapper per sample whatever the
number of modes; counting the modes reads one small tensor back from the device.

**sRGB inputs** (``input_space="srgb"``) are display-referred images in [0, 1]: they are decoded
to linear, graded, encoded again and clamped to [0, 1], the display range they came from. They
are not tone mapped unless ``tonemap`` is given (then the decoded values are treated as
scene-referred linear, for example after a positive exposure).

**Skipped samples** (probability ``1 - p``) are blended back with ``torch.where``, so one graph
serves the whole batch and a skipped sample's output equals its input exactly: with a tone mapper
and ``p < 1`` skipped samples stay scene-referred (to tone map every sample, follow the layer with
:class:`torchgrade.ToneMap`). ``p = 0`` returns the input without computing anything.

**Precision.** float16 and bfloat16 inputs are computed in float32 and returned in their own dtype.
"""

from __future__ import annotations

import math
import numbers

import torch
from torch import nn

from .bloom import BLOOM_MODES, Bloom, bloom
from .color import linear_to_srgb, srgb_to_linear
from .core import check_image, to_input_dtype, working_dtype
from .grade import ColorGrade, color_grade
from .tonemap import TONEMAP_MODES, tonemap

__all__ = ["RandomPostFX", "tonemap_per_sample", "GRADE_CONTROLS", "BLOOM_CONTROLS", "COLOUR_CONTROLS", "INPUT_SPACES"]

GRADE_CONTROLS = (
    "post_exposure",
    "temperature",
    "tint",
    "contrast",
    "split_shadows",
    "split_highlights",
    "split_balance",
    "hue_shift",
    "saturation",
)
"""The :func:`torchgrade.grade.color_grade` controls ``RandomPostFX`` samples, in Unity's order."""

COLOUR_CONTROLS = ("split_shadows", "split_highlights")
"""Controls sampled as an RGB colour: each channel drawn independently inside the range."""

BLOOM_CONTROLS = {f"bloom_{name}": (name, Bloom.controls[name].range) for name in ("threshold", "intensity", "scatter")}
"""Bloom controls: the argument of :func:`torchgrade.bloom.bloom` each one sets, and its range (``Bloom``'s own)."""

INPUT_SPACES = ("linear", "srgb")


def _checked_range(name: str, value, allowed: tuple) -> tuple | None:
    """``value`` as a ``(min, max)`` pair of floats, or None; ``ValueError`` naming ``name`` otherwise."""
    if value is None:
        return None
    low, high = allowed
    message = f"{name} must be None or a (min, max) pair with min <= max inside [{low}, {high}], got {value!r}"
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError(message)
    if any(isinstance(v, bool) or not isinstance(v, numbers.Real) for v in value):
        raise ValueError(message)
    pair = (float(value[0]), float(value[1]))
    if not (low <= pair[0] <= pair[1] <= high) or not all(math.isfinite(v) for v in pair):
        raise ValueError(message)
    return pair


def _is_identity(name: str, pair: tuple) -> bool:
    """True when a grading range is the single value at which the control changes nothing."""
    identity = ColorGrade.controls[name].default
    identity = identity[0] if isinstance(identity, tuple) else identity
    return pair[0] == pair[1] == identity


def _checked_tonemap(value) -> tuple:
    """``tonemap`` as a tuple of mode names (empty for None)."""
    if value is None:
        return ()
    modes = (value,) if isinstance(value, str) else tuple(value)
    if not modes or any(mode not in TONEMAP_MODES for mode in modes):
        raise ValueError(f"tonemap must be None, one of {TONEMAP_MODES} or a non-empty sequence of them, got {value!r}")
    return modes


def tonemap_per_sample(images: torch.Tensor, choice: torch.Tensor, modes: tuple) -> torch.Tensor:
    """Tone map sample ``i`` of ``images`` with ``modes[choice[i]]``, each mode evaluated once on its samples.

    Examples:
        >>> images = torch.full((2, 3, 1, 1), 4.0)
        >>> out = tonemap_per_sample(images, torch.tensor([1, 0]), ("none", "reinhard"))
        >>> out.flatten().tolist()
        [0.800000011920929, 0.800000011920929, 0.800000011920929, 1.0, 1.0, 1.0]
    """
    if len(modes) == 1:
        return tonemap(images, modes[0])
    order = torch.argsort(choice, stable=True)
    counts = torch.bincount(choice, minlength=len(modes)).tolist()
    groups = images.index_select(0, order).split(counts)
    mapped = torch.cat([tonemap(group, mode) for group, mode in zip(groups, modes) if len(group)])
    return mapped.index_select(0, torch.argsort(order))


class RandomPostFX(nn.Module):
    """Random per-sample post-processing of a batch ``(B, 3, H, W)`` (or one image ``(3, H, W)``).

    Args:
        post_exposure, temperature, tint, contrast, split_balance, hue_shift, saturation: ``(min, max)``
            ranges in :class:`torchgrade.ColorGrade`'s units (stops; -100..100; hue in degrees), or None.
        split_shadows, split_highlights: ``(min, max)`` range of each gamma-space channel of the
            split-toning colours, inside [0, 1] (0.5 is neutral), or None. ``split_balance`` needs one of them.
        bloom_threshold, bloom_intensity, bloom_scatter: ``(min, max)`` ranges of :func:`torchgrade.bloom.bloom`'s
            controls (threshold in gamma space), or None. Bloom runs when any of them is given (unless
            ``bloom_intensity=(0, 0)``); the others keep ``Bloom``'s defaults. ``bloom_scatter`` needs ``bloom_mode="scattering"``.
        bloom_mode: ``"additive"`` or ``"scattering"``.
        tonemap: None (no tone mapping), a mode of :data:`torchgrade.TONEMAP_MODES`, or a sequence of
            modes chosen uniformly per sample.
        aces: grade in ACEScc/ACEScg as :class:`torchgrade.ColorGrade` does.
        input_space: ``"linear"`` (scene-referred HDR) or ``"srgb"`` (sRGB-encoded LDR in [0, 1]).
        p: probability that a sample is changed; the others are returned unchanged.
        same_on_batch: one draw for the whole batch (kornia's meaning, ``p`` included).
        keepdim: return a single ``(3, H, W)`` image as ``(3, H, W)`` rather than ``(1, 3, H, W)``.

    ``forward(x, generator=None, params=None)``: parameters are drawn from ``generator`` (a
    ``torch.Generator``; the global generator when None), or taken from ``params`` to replay a
    previous draw. The parameters used are kept in ``last_params`` (see :meth:`sample_params`).

    Examples:
        >>> augment = RandomPostFX(contrast=(-30, 30), saturation=(-20, 20), tonemap="neutral")
        >>> images = torch.rand(4, 3, 8, 8) * 4
        >>> out = augment(images, generator=torch.Generator().manual_seed(0))
        >>> sorted(augment.last_params)
        ['batch_prob', 'contrast', 'saturation', 'tonemap']
        >>> torch.equal(augment(images, params=augment.last_params), out)  # replayed exactly
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
        aces: bool = False,
        input_space: str = "linear",
        p: float = 1.0,
        same_on_batch: bool = False,
        keepdim: bool = False,
    ):
        super().__init__()
        given = dict(locals())  # the range arguments, by name
        grade_ranges = {name: _checked_range(name, given[name], ColorGrade.controls[name].range) for name in GRADE_CONTROLS}
        self.grade_ranges = {name: r for name, r in grade_ranges.items() if r is not None and not _is_identity(name, r)}
        bloom_ranges = {name: _checked_range(name, given[name], allowed) for name, (_, allowed) in BLOOM_CONTROLS.items()}
        self.bloom_ranges = {name: r for name, r in bloom_ranges.items() if r is not None}
        if self.bloom_ranges.get("bloom_intensity") == (0.0, 0.0):
            self.bloom_ranges = {}
        self.bloom_mode = bloom_mode
        self.tonemap = _checked_tonemap(tonemap)
        self.aces = bool(aces)
        self.input_space = input_space
        self.p = p
        self.same_on_batch = bool(same_on_batch)
        self.keepdim = bool(keepdim)
        self._check_settings()
        self.last_params: dict | None = None

    def _check_settings(self) -> None:
        if self.bloom_mode not in BLOOM_MODES:
            raise ValueError(f"bloom_mode must be one of {BLOOM_MODES}, got {self.bloom_mode!r}")
        if "bloom_scatter" in self.bloom_ranges and self.bloom_mode != "scattering":
            raise ValueError('bloom_scatter only acts in scattering mode: pass bloom_mode="scattering"')
        if "split_balance" in self.grade_ranges and not set(COLOUR_CONTROLS) & set(self.grade_ranges):
            raise ValueError("split_balance changes nothing without split_shadows or split_highlights")
        if self.input_space not in INPUT_SPACES:
            raise ValueError(f"input_space must be one of {INPUT_SPACES}, got {self.input_space!r}")
        if isinstance(self.p, bool) or not isinstance(self.p, numbers.Real) or not 0.0 <= self.p <= 1.0:
            raise ValueError(f"p must be a probability in [0, 1], got {self.p!r}")

    @property
    def ranges(self) -> dict:
        """The ranges sampled, by control name, in sampling order."""
        return {**self.bloom_ranges, **self.grade_ranges}

    @property
    def is_identity(self) -> bool:
        """True when no control, bloom or tone mapper is on: the layer then returns its input."""
        return not (self.ranges or self.tonemap)

    def _widths(self) -> list:
        return [3 if name in COLOUR_CONTROLS else 1 for name in self.ranges]

    def sample_params(self, batch_size: int, generator: torch.Generator | None = None, device=None) -> dict:
        """Draw the parameters of a batch in one call to ``torch.rand`` (kornia's ``forward_parameters``).

        Returns a dict of tensors on ``device``: ``"batch_prob"`` (B,) bool, which samples are changed
        (kornia's name); one entry per sampled control, (B,) or (B, 3) for colours, in its units;
        ``"tonemap"`` (B,) int64, the index of each sample's mode in ``self.tonemap``, when tone mapping.
        Draws happen on the generator's device (CPU when None), so a seed gives the same look on any device.
        """
        rows = 1 if self.same_on_batch else batch_size
        widths = self._widths()
        columns = 1 + sum(widths) + (1 if self.tonemap else 0)
        draw_device = generator.device if generator is not None else torch.device("cpu")
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

    def _param_names(self) -> set:
        return {"batch_prob", *self.ranges, *(("tonemap",) if self.tonemap else ())}

    def _checked_params(self, params: dict, images: torch.Tensor) -> dict:
        """Replayed parameters, checked against this layer's controls and the batch, on the images' device."""
        expected = self._param_names()
        if not isinstance(params, dict) or set(params) != expected:
            given = sorted(params) if isinstance(params, dict) else type(params).__name__
            raise ValueError(f"params must be a dict with keys {sorted(expected)} (see last_params), got {given}")
        batch = images.shape[0]
        for name, value in params.items():
            if not isinstance(value, torch.Tensor) or value.dim() == 0 or value.shape[0] != batch:
                raise ValueError(f"params[{name!r}] must be a tensor with {batch} per-sample values, got {value!r}")
        return {name: value.to(images.device) for name, value in params.items()}

    def transform(self, images: torch.Tensor, params: dict) -> torch.Tensor:
        """Apply ``params`` to every sample of ``images`` (B, 3, H, W), ignoring ``batch_prob``."""
        x = working_dtype(images)
        if self.input_space == "srgb":
            x = srgb_to_linear(x)
        if self.bloom_ranges:
            controls = {BLOOM_CONTROLS[name][0]: params[name] for name in self.bloom_ranges}
            x = bloom(x, mode=self.bloom_mode, **controls)
        x = color_grade(x, aces=self.aces, **{name: params[name] for name in self.grade_ranges})
        if self.tonemap:
            x = tonemap_per_sample(x, params["tonemap"], self.tonemap)
        if self.input_space == "srgb":
            x = linear_to_srgb(x).clamp(0.0, 1.0)
        return to_input_dtype(x, images)

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None, params: dict | None = None) -> torch.Tensor:
        check_image(x)
        if x.dim() not in (3, 4):
            raise ValueError(f"RandomPostFX takes (3, H, W) or (B, 3, H, W) images, got shape {tuple(x.shape)}")
        images = x if x.dim() == 4 else x.unsqueeze(0)
        if params is None:
            params = self.sample_params(images.shape[0], generator, images.device)
        else:
            params = self._checked_params(params, images)
        self.last_params = params
        if self.p == 0 or self.is_identity:
            out = images
        else:
            applied = params["batch_prob"].reshape(-1, 1, 1, 1)
            out = torch.where(applied, self.transform(images, params), images)
        return out.squeeze(0) if self.keepdim and x.dim() == 3 else out

    def extra_repr(self) -> str:
        settings = [f"{name}={r}" for name, r in self.ranges.items()]
        if self.bloom_ranges:
            settings.append(f"bloom_mode={self.bloom_mode!r}")
        if self.tonemap:
            settings.append(f"tonemap={self.tonemap}")
        if self.aces:
            settings.append("aces=True")
        settings += [f"input_space={self.input_space!r}", f"p={self.p}", f"same_on_batch={self.same_on_batch}"]
        return ", ".join(settings)
