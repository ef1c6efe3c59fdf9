"""The registry of tone mappers: each mode's curve and controls, and :func:`tonemap`, which applies one by name.

A new tone mapper is one file in this package (its curve, ending with
:func:`~torchgrade.tonemap.base.display`, and the ranges of its parameters) plus its entry here.
"""

from __future__ import annotations

import torch

from ..base.images import check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import Param, check_choice
from .aces1.reference import aces_reference
from .aces2.curves import (
    ACES2_HDR_RANGES,
    aces2_hdr,
    aces2_sdr,
    prepare_aces2_hdr,
    prepare_aces2_sdr,
)
from .aces1.fits import aces, aces_hill, aces_narkowicz
from .agx_curves import agx, agx_godot
from ..base.controls import check_given
from .base import WHITE_POINT_RANGE, ToneMapper, no_tonemap
from .filmic_curves import (
    FILMIC_RANGES,
    HABLE_RANGES,
    UNREAL_FILMIC_RANGES,
    filmic,
    hable,
    neutral,
    unreal_filmic,
)
from .hdr_range import HDR_PRIMARIES, NEUTRAL_HDR_RANGES, neutral_hdr
from .khronos_pbr import khronos_pbr_neutral
from .reinhard_curves import reinhard, reinhard_extended, reinhard_luminance

__all__ = ["TONE_MAPPERS", "TONEMAP_MODES", "HDR_MODES", "tone_mapper", "check_curve_params", "tonemap", "tone_mapped"]

TONE_MAPPERS = {
    "none": ToneMapper.of(no_tonemap),
    "reinhard": ToneMapper.of(reinhard),
    "reinhard_extended": ToneMapper.of(reinhard_extended, white_point=WHITE_POINT_RANGE),
    "reinhard_luminance": ToneMapper.of(reinhard_luminance, white_point=WHITE_POINT_RANGE),
    "neutral": ToneMapper.of(neutral),
    "aces": ToneMapper.of(aces, takes_planes=True),
    "hable": ToneMapper.with_ranges(hable, HABLE_RANGES),
    "filmic": ToneMapper.with_ranges(filmic, FILMIC_RANGES),
    "unreal_filmic": ToneMapper.with_ranges(unreal_filmic, UNREAL_FILMIC_RANGES),
    "aces_reference": ToneMapper.of(aces_reference),
    "aces_hill": ToneMapper.of(aces_hill),
    "aces_narkowicz": ToneMapper.of(aces_narkowicz),
    "agx": ToneMapper.of(agx),
    "agx_godot": ToneMapper.of(agx_godot),
    "khronos_pbr_neutral": ToneMapper.of(khronos_pbr_neutral),
    "aces2": ToneMapper.of(aces2_sdr, prepare=prepare_aces2_sdr, takes_nan_free=True, takes_planes=True),
    "aces2_hdr": ToneMapper.with_ranges(aces2_hdr, ACES2_HDR_RANGES, prepare_aces2_hdr, takes_nan_free=True, takes_planes=True),
    "neutral_hdr": ToneMapper.with_ranges(neutral_hdr, NEUTRAL_HDR_RANGES),
}
"""Every tone mapper by mode name: its curve and its controls (defaults are the curve's own)."""

TONEMAP_MODES = tuple(TONE_MAPPERS)
"""Every ``ToneMap`` mode."""


HDR_MODES = {"aces2_hdr": HDR_PRIMARIES, "neutral_hdr": HDR_PRIMARIES}
"""The modes for HDR displays and the primaries of their output, display-linear with 1.0 = their
``peak_luminance``; every other mode returns Rec.709 with 1.0 = SDR white."""


def tone_mapper(mode: str) -> ToneMapper:
    """The registry entry of ``mode``; ``ValueError`` naming the known modes for any other.

    Examples:
        >>> list(tone_mapper("hable").controls)
        ['exposure_bias', 'white_point']
        >>> tone_mapper("filmic2")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: unknown tone mapping mode 'filmic2': mode must be one of 'none', ...
    """
    try:
        check_choice("mode", mode, TONEMAP_MODES)
    except ValueError as error:
        raise ValueError(f"unknown tone mapping mode {mode!r}: {error}") from None
    return TONE_MAPPERS[mode]


def check_curve_params(mode: str, names) -> None:
    """Raise ``ValueError`` naming the first of ``names`` that tone mapper ``mode`` does not take, and those it takes:
    the one check of a mode's parameter names, for :class:`~torchgrade.ToneMap`, :func:`tonemap` and :func:`tone_mapped`.

    Examples:
        >>> check_curve_params("agx", ["slope"])
        Traceback (most recent call last):
        ...
        ValueError: tone mapper 'agx' takes no 'slope'; it takes no parameters
    """
    controls = tone_mapper(mode).controls
    for name in names:
        if name not in controls:
            raise ValueError(f"tone mapper {mode!r} takes no {name!r}; it takes {list(controls) or 'no parameters'}")


def tonemap(image: torch.Tensor, mode: str = "neutral", clip: bool = True, **params: Param) -> torch.Tensor:
    """Apply tone mapper ``mode`` (one of :data:`TONEMAP_MODES`) with its parameters.

    The input passes the library's non-finite policy first; float16/bfloat16 inputs are computed in
    float32 and returned in their own dtype. ``clip=False`` skips the final clip to [0, 1] (used
    when baking a LUT that clips after its lookup, :func:`torchgrade.lut.bake_lut`). Parameters given as numbers are
    checked as :class:`~torchgrade.ToneMap` checks them (the mode's controls,
    :func:`~torchgrade.base.controls.check_given`); tensors are taken as they are.

    Examples:
        >>> image = torch.full((1, 3, 1, 1), 8.0)
        >>> tonemap(image, "reinhard_extended", white_point=4.0).flatten().tolist()
        [1.0, 1.0, 1.0]
        >>> tonemap(image, "reinhard_luminance", clip=False, white_point=4.0).flatten().tolist()
        [1.333333134651184, 1.333333134651184, 1.333333134651184]
        >>> tonemap(image, "hable", white_point=-1.0)
        Traceback (most recent call last):
        ...
        ValueError: white_point must lie in [0.001, 10000.0], got -1.0
    """
    check_curve_params(mode, params)
    check_given(tone_mapper(mode).controls, params, f"ToneMap({mode!r})")
    return tone_mapped(image, mode, clip, nan_free=False, planes=False, **params)


def tone_mapped(image: torch.Tensor, mode: str = "neutral", clip: bool = True, *, nan_free: bool = False,
                planes: bool = False, **params: Param) -> torch.Tensor:
    """:func:`tonemap` without checking the parameters' values: for :class:`~torchgrade.ToneMap`, which checked them
    when they were set, on every strip of a frame. ``nan_free``: ``image`` holds no NaN
    (:func:`~torchgrade.base.images.sanitize`); ``planes``: a curve that can computes on the image's three planes
    (:attr:`~torchgrade.tonemap.base.ToneMapper.takes_planes`).

    Examples:
        >>> image = torch.full((1, 3, 1, 1), 8.0)
        >>> torch.equal(tone_mapped(image, "hable"), tonemap(image, "hable"))
        True
    """
    check_image(image)
    entry = tone_mapper(mode)
    check_curve_params(mode, params)
    working = sanitize(working_dtype(image), nan_free=nan_free)
    options = {"nan_free": True} if entry.takes_nan_free else {}  # a curve that sanitizes again leaves out the NaN pass
    if entry.takes_planes:
        options["planes"] = planes
    return to_input_dtype(entry.curve(working, clip=clip, **options, **params), image)
