"""The filmic family: Hable's curve (Uncharted 2, and with its six parameters exposed), Unity's Neutral, Unreal's film curve."""

from __future__ import annotations

import math

import torch

from ..base.params import Param, scalar_param
from ..color import convert, unity_to_aces
from ..runtime import constant
from .aces1.rrt import (
    ODT_SAT_FACTOR,
    RRT_SAT_FACTOR,
    ap1_desaturate,
    ap1_to_rec709,
    rrt_glow_and_red_modifier,
    smoothstep_hue_weight,
)
from .base import WHITE_POINT_RANGE, display, limited

__all__ = ["HABLE_RANGES", "FILMIC_RANGES", "UNREAL_FILMIC_RANGES", "neutral", "filmic", "hable", "unreal_filmic"]

HABLE_RANGES = {"exposure_bias": (1e-3, 1e3), "white_point": WHITE_POINT_RANGE}
"""Valid ``[low, high]`` of :func:`hable`'s parameters."""

FILMIC_RANGES = {
    "shoulder_strength": (0.0, 10.0),
    "linear_strength": (0.0, 10.0),
    "linear_angle": (0.0, 10.0),
    "toe_strength": (1e-3, 10.0),
    "toe_numerator": (0.0, 10.0),
    "toe_denominator": (1e-3, 10.0),
    "white_point": WHITE_POINT_RANGE,
    "exposure_bias": HABLE_RANGES["exposure_bias"],
}
"""Valid ``[low, high]`` of :func:`filmic`'s parameters: toe strength and denominator stay positive so ``t``'s denominator does."""

UNREAL_FILMIC_RANGES = {"slope": (0.01, 1.0), "toe": (0.0, 0.99), "shoulder": (0.0, 0.99), "black_clip": (0.0, 1.0), "white_clip": (0.0, 1.0)}
"""Valid ``[low, high]`` of :func:`unreal_filmic`'s parameters: toe and shoulder stop at 0.99 (at 1, with a zero
clip, its toe or shoulder scale is 0)."""


def _hable_curve(x: torch.Tensor, a, b, c, d, e, f) -> torch.Tensor:
    """Hable's filmic curve ``t(x) = (x (a x + c b) + d e) / (x (a x + b) + d f) - e / f``."""
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


_FLAT_CURVE = 1e-6
"""Smallest ``t(white_point)`` :func:`filmic` divides by."""

_NEUTRAL = dict(a=0.2, b=0.29, c=0.24, d=0.272, e=0.02, f=0.3)
_NEUTRAL_WHITE_LEVEL = 5.3


def neutral(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """Unity's Neutral tone mapper (``NeutralTonemap``, Color.hlsl): ``t(x·s)·s`` with ``s = 1 / t(5.3)``.

    ``t`` is Hable's curve with a=0.2, b=0.29, c=0.24, d=0.272, e=0.02, f=0.3; the effective white
    point, where the output reaches 1, is ``5.3 / s ≈ 4.035``.

    Examples:
        >>> [round(v, 3) for v in neutral(torch.tensor([0.18, 1.0, 5.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.182, 0.631, 1.0]
    """
    white = constant(_NEUTRAL_WHITE_LEVEL, image)
    scale = 1.0 / _hable_curve(white, **_NEUTRAL)
    return display(_hable_curve(limited(image) * scale, **_NEUTRAL) * scale, clip)


def filmic(
    image: torch.Tensor,
    shoulder_strength: Param = 0.15,
    linear_strength: Param = 0.50,
    linear_angle: Param = 0.10,
    toe_strength: Param = 0.20,
    toe_numerator: Param = 0.02,
    toe_denominator: Param = 0.30,
    white_point: Param = 11.2,
    exposure_bias: Param = 2.0,
    clip: bool = True,
) -> torch.Tensor:
    """Hable's filmic curve with its six parameters exposed: ``t(x · bias) / t(w)`` (Hable 2010, slides 142-143).

    ``t`` is Hable's curve ``(x (A x + C B) + D E) / (x (A x + B) + D F) - E / F`` with A = shoulder
    strength, B = linear strength, C = linear angle, D = toe strength, E = toe numerator, F = toe
    denominator (HDRP's and Unreal's "custom" filmic controls). The defaults are Uncharted 2's (A=0.15,
    B=0.50, C=0.10, D=0.20, E=0.02, F=0.30, W=11.2, bias 2), so ``filmic`` with defaults is :func:`hable`.
    Since ``t(x) = x (A (F - E) x + B (C F - E)) / (F (x (A x + B) + D F))``, the curve rises from 0 when
    ``E ≤ F`` and ``E ≤ C F``. The normaliser ``t(w)`` is kept at least 1e-6: parameters inside their
    ranges can make the curve flat at ``w`` (``A = 0`` with ``C = E / F``, or ``A = B = 0``), and the
    picture is then black instead of 0/0.

    Examples:
        >>> [round(v, 3) for v in filmic(torch.tensor([0.18, 1.0, 5.6]).expand(3, 1, 3))[0, 0].tolist()]
        [0.128, 0.493, 1.0]
    """
    names = ("shoulder_strength", "linear_strength", "linear_angle", "toe_strength", "toe_numerator", "toe_denominator")
    values = (shoulder_strength, linear_strength, linear_angle, toe_strength, toe_numerator, toe_denominator)
    k = [scalar_param(value, image, name) for value, name in zip(values, names)]
    bias = scalar_param(exposure_bias, image, "exposure_bias")
    w = scalar_param(white_point, image, "white_point")
    return display(_hable_curve(limited(image) * bias, *k) / _hable_curve(w, *k).clamp_min(_FLAT_CURVE), clip)


def hable(image: torch.Tensor, exposure_bias: Param = 2.0, white_point: Param = 11.2, clip: bool = True) -> torch.Tensor:
    """Uncharted 2 filmic curve: ``t(x · bias) / t(w)`` (Hable 2010, slides 142-143; HDR §3.4).

    Constants A=0.15, B=0.50, C=0.10, D=0.20, E=0.02, F=0.30, exposure bias 2 and white point 11.2:
    :func:`filmic` with its default curve.

    Examples:
        >>> hable(torch.full((3, 1, 1), 5.6)).flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    return filmic(image, exposure_bias=exposure_bias, white_point=white_point, clip=clip)


def _nonzero(x: torch.Tensor, floor: float) -> torch.Tensor:
    """``x`` with its magnitude kept at least ``floor``, sign kept (0 counts as positive)."""
    return torch.where(x < 0, x.clamp(max=-floor), x.clamp(min=floor))


def _film_curve(log_c, slope, toe, shoulder, black_clip, white_clip) -> torch.Tensor:
    """Unreal's toe / straight / shoulder curve of ``log10`` colour (``FilmToneMap``, TonemapCommon.ush).

    Straight line ``slope (log c + straight_match)`` through (0.18, 0.18), a logistic toe down to
    ``-black_clip`` and shoulder up to ``1 + white_clip``, blended by a smoothstep between the match points.
    """
    toe_scale = 1.0 + black_clip - toe
    shoulder_scale = 1.0 + white_clip - shoulder
    log_grey = math.log10(0.18)
    # Toe above 0.8: grey lies on the straight segment; else on the toe. atanh is only evaluated in its
    # domain: bt lies in [-0.82, -0.016] whenever toe <= 0.8.
    bt = ((0.18 + black_clip) / toe_scale - 1.0).clamp(-0.99, 0.99)
    toe_match = torch.where(
        toe > 0.8, (1.0 - toe - 0.18) / slope + log_grey, log_grey - torch.atanh(bt) * (toe_scale / slope)
    )
    straight_match = (1.0 - toe) / slope - toe_match
    shoulder_match = shoulder / slope - straight_match

    straight = slope * (log_c + straight_match)
    toe_curve = -black_clip + 2.0 * toe_scale * torch.sigmoid((2.0 * slope / toe_scale) * (log_c - toe_match))
    shoulder_curve = (1.0 + white_clip) - 2.0 * shoulder_scale * torch.sigmoid(
        (2.0 * slope / shoulder_scale) * (shoulder_match - log_c)
    )
    toe_part = torch.where(log_c < toe_match, toe_curve, straight)
    shoulder_part = torch.where(log_c > shoulder_match, shoulder_curve, straight)
    t = ((log_c - toe_match) / _nonzero(shoulder_match - toe_match, 1e-6)).clamp(0.0, 1.0)
    t = torch.where(shoulder_match < toe_match, 1.0 - t, t)
    t = (3.0 - 2.0 * t) * t * t
    return toe_part + t * (shoulder_part - toe_part)


def unreal_filmic(
    image: torch.Tensor,
    slope: Param = 0.88,
    toe: Param = 0.55,
    shoulder: Param = 0.26,
    black_clip: Param = 0.0,
    white_clip: Param = 0.04,
    clip: bool = True,
) -> torch.Tensor:
    """Unreal Engine 4.15+'s filmic tone mapper (``FilmToneMap``) with its five controls and defaults.

    Linear Rec.709 → ACES2065-1; RRT glow and red modifier (Unreal's smoothstep hue weight); ACEScg,
    clamped at 0; desaturation 0.96; the toe / straight / shoulder film curve per channel on ``log10``;
    desaturation 0.93; clamped at 0; back to linear Rec.709.

    Examples:
        >>> [round(v, 3) for v in unreal_filmic(torch.tensor([0.18, 1.0, 5.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.18, 0.723, 0.962]
    """
    names = ("slope", "toe", "shoulder", "black_clip", "white_clip")
    k = [scalar_param(v, image, n) for v, n in zip((slope, toe, shoulder, black_clip, white_clip), names)]
    aces = rrt_glow_and_red_modifier(unity_to_aces(limited(image)), smoothstep_hue_weight)
    acescg = ap1_desaturate(convert(aces, "ap0_to_ap1").clamp_min(0.0), RRT_SAT_FACTOR)
    log_c = torch.log10(acescg.clamp_min(torch.finfo(acescg.dtype).tiny))
    toned = ap1_desaturate(_film_curve(log_c, *k), ODT_SAT_FACTOR).clamp_min(0.0)
    return display(ap1_to_rec709(toned), clip)
