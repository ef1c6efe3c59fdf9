"""Colour science on ``(..., 3, H, W)`` tensors: luminance, sRGB, LogC, ACES, LMS, HSV, primaries
and display encodings (PQ, HLG).

All functions are differentiable and safe: no NaN or Inf in outputs or gradients at 0, at grey
pixels (undefined hue), or at very large values. Branches are computed with ``torch.where`` on
guarded arguments, so the branch not taken never produces an infinite gradient.

Constants are Unity's (``com.unity.render-pipelines.core/ShaderLibrary/Color.hlsl`` and
``ACES.hlsl``), so grades typed in from Unity's inspector reproduce Unity's numbers; the primaries
and display encodings are the standards' (ITU-R BT.2020 and BT.2100, SMPTE ST 2084 and EG 432-1, Academy
S-2016-001).
"""

from __future__ import annotations

import math

import torch

from .core import apply_matrix

__all__ = [
    "CHANNEL", "REC709_LUMINANCE", "AP1_LUMINANCE", "MATRICES", "matrix", "convert", "luminance", "safe_pow",
    "safe_sqrt", "linear_to_srgb", "srgb_to_linear", "linear_to_logc", "logc_to_linear", "ACESCC_MIDGRAY",
    "ACESCC_MAX", "aces_to_acescc", "acescc_to_aces", "linear_to_acescct", "acescct_to_linear",
    "unity_to_aces", "aces_to_unity", "unity_to_acescg", "acescg_to_unity", "aces_to_acescg",
    "acescg_to_aces", "linear_to_lms", "lms_to_linear", "rgb_to_hsv", "hsv_to_rgb", "REC709_CHROMATICITIES",
    "AP0_CHROMATICITIES", "AP1_CHROMATICITIES", "REC2020_CHROMATICITIES", "P3_D65_CHROMATICITIES",
    "rgb_to_xyz_matrix", "bradford_adaptation", "primaries_to_rec709_matrix", "linear_to_pq", "pq_to_linear",
    "hlg_oetf", "hlg_inverse_oetf",
]

CHANNEL = -3
"""The colour-channel dimension of every image tensor."""

REC709_LUMINANCE = (0.2126729, 0.7151522, 0.0721750)
"""Y of linear Rec.709/sRGB primaries, D65 (Unity ``Luminance``)."""

AP1_LUMINANCE = (0.272229, 0.674082, 0.0536895)
"""Y of linear ACEScg (AP1) primaries (Unity ``AP1_RGB2Y``)."""

# ACES primaries conversions (Unity ACES.hlsl; from aces-dev README-MATRIX). The sRGB<->AP1
# matrices are derived from these in float64 so that every round trip is exact to rounding.
_SRGB_TO_AP0 = (
    (0.4397010, 0.3829780, 0.1773350),
    (0.0897923, 0.8134230, 0.0967616),
    (0.0175440, 0.1115440, 0.8707040),
)
_AP0_TO_AP1 = (
    (1.4514393161, -0.2365107469, -0.2149285693),
    (-0.0765537734, 1.1762296998, -0.0996759264),
    (0.0083161484, -0.0060324498, 0.9977163014),
)
_AP1_TO_XYZ = (
    (0.6624541811, 0.1340042065, 0.1561876870),
    (0.2722287168, 0.6740817658, 0.0536895174),
    (-0.0055746495, 0.0040607335, 1.0103391003),
)
_XYZ_TO_REC709 = (
    (3.2409699419, -1.5373831776, -0.4986107603),
    (-0.9692436363, 1.8759675015, 0.0415550574),
    (0.0556300797, -0.2039769589, 1.0569715142),
)
_D60_TO_D65_CAT = (
    (0.98722400, -0.00611327, 0.0159533),
    (-0.00759836, 1.00186000, 0.0053302),
    (0.00307257, -0.00509595, 1.0816800),
)
# Linear Rec.709 <-> LMS (Unity LinearToLMS / LMSToLinear, CAT02-based).
_LINEAR_TO_LMS = (
    (3.90405e-1, 5.49941e-1, 8.92632e-3),
    (7.08416e-2, 9.63172e-1, 1.35775e-3),
    (2.31082e-2, 1.28021e-1, 9.36245e-1),
)
_LMS_TO_LINEAR = (
    (2.85847e0, -1.62879e0, -2.48910e-2),
    (-2.10182e-1, 1.15820e0, 3.24281e-4),
    (-4.18120e-2, -1.18169e-1, 1.06867e0),
)


def _m(rows) -> torch.Tensor:
    return torch.tensor(rows, dtype=torch.float64)


MATRICES = {
    "srgb_to_ap0": _m(_SRGB_TO_AP0),
    "ap0_to_ap1": _m(_AP0_TO_AP1),
    "ap1_to_xyz": _m(_AP1_TO_XYZ),
    "xyz_to_rec709": _m(_XYZ_TO_REC709),
    "d60_to_d65": _m(_D60_TO_D65_CAT),
    "linear_to_lms": _m(_LINEAR_TO_LMS),
    "lms_to_linear": _m(_LMS_TO_LINEAR),
}
MATRICES["ap0_to_srgb"] = torch.linalg.inv(MATRICES["srgb_to_ap0"])
MATRICES["ap1_to_ap0"] = torch.linalg.inv(MATRICES["ap0_to_ap1"])
MATRICES["srgb_to_ap1"] = MATRICES["ap0_to_ap1"] @ MATRICES["srgb_to_ap0"]
MATRICES["ap1_to_srgb"] = torch.linalg.inv(MATRICES["srgb_to_ap1"])
MATRICES["xyz_to_ap1"] = torch.linalg.inv(MATRICES["ap1_to_xyz"])


def matrix(name: str, like: torch.Tensor) -> torch.Tensor:
    """One of :data:`MATRICES` in ``like``'s dtype and device.

    Examples:
        >>> m = matrix("srgb_to_ap1", torch.zeros(1, dtype=torch.float64))
        >>> m.shape, m.dtype
        (torch.Size([3, 3]), torch.float64)
    """
    return MATRICES[name].to(device=like.device, dtype=like.dtype)


def convert(image: torch.Tensor, name: str) -> torch.Tensor:
    """Apply the named 3x3 matrix of :data:`MATRICES` to every pixel.

    Examples:
        >>> [round(v, 4) for v in convert(torch.ones(1, 3, 1, 1), "ap0_to_ap1").flatten().tolist()]
        [1.0, 1.0, 1.0]
    """
    return apply_matrix(matrix(name, image), image)


def luminance(image: torch.Tensor, weights: str = "rec709") -> torch.Tensor:
    """Relative luminance ``Y = w · rgb`` as ``(..., 1, H, W)``; ``weights`` is ``"rec709"`` or ``"ap1"``.

    Examples:
        >>> luminance(torch.ones(1, 3, 2, 2)).shape
        torch.Size([1, 1, 2, 2])
        >>> round(float(luminance(torch.ones(1, 3, 1, 1))), 4)
        1.0
    """
    w = {"rec709": REC709_LUMINANCE, "ap1": AP1_LUMINANCE}[weights]
    w = torch.tensor(w, dtype=image.dtype, device=image.device).reshape(3, 1, 1)
    return (image * w).sum(dim=CHANNEL, keepdim=True)


def safe_pow(x: torch.Tensor, exponent) -> torch.Tensor:
    """``max(x, 0) ** exponent`` with a finite gradient at 0 (HLSL ``PositivePow`` on clamped input).

    Examples:
        >>> safe_pow(torch.tensor([-1.0, 0.0, 4.0]), 0.5).tolist()
        [0.0, 0.0, 2.0]
    """
    positive = x > 0
    return torch.where(positive, torch.where(positive, x, torch.ones_like(x)) ** exponent, torch.zeros_like(x))


def safe_sqrt(x: torch.Tensor) -> torch.Tensor:
    """``sqrt(max(x, 0))`` with gradient 0 (not Inf) at 0.

    Examples:
        >>> safe_sqrt(torch.tensor([-4.0, 0.0, 9.0])).tolist()
        [0.0, 0.0, 3.0]
    """
    return safe_pow(x, 0.5)


def linear_to_srgb(image: torch.Tensor) -> torch.Tensor:
    """IEC 61966-2-1 sRGB encoding: ``12.92 x`` below 0.0031308, else ``1.055 x^(1/2.4) - 0.055``.

    Examples:
        >>> [round(v, 4) for v in linear_to_srgb(torch.tensor([0.0, 0.18, 1.0])).flatten().tolist()]
        [0.0, 0.4614, 1.0]
    """
    high = 1.055 * image.clamp_min(0.0031308) ** (1.0 / 2.4) - 0.055
    return torch.where(image <= 0.0031308, 12.92 * image, high)


def srgb_to_linear(image: torch.Tensor) -> torch.Tensor:
    """IEC 61966-2-1 sRGB decoding: ``c / 12.92`` up to 0.04045, else ``((c + 0.055) / 1.055)^2.4``.

    Examples:
        >>> [round(v, 4) for v in srgb_to_linear(torch.tensor([0.0, 0.5, 1.0])).flatten().tolist()]
        [0.0, 0.214, 1.0]
    """
    high = ((image.clamp_min(0.04045) + 0.055) / 1.055) ** 2.4
    return torch.where(image <= 0.04045, image / 12.92, high)


# ARRI LogC (v3) curve with the constants Unity uses (ARRI's EI 1000 table), and Unity's fast form:
# the logarithmic segment everywhere, ``c log10(a x + b) + d``. Its range tops out at ~58.86.
LOGC_CUT, LOGC_A, LOGC_B, LOGC_C, LOGC_D = 0.011361, 5.555556, 0.047996, 0.244161, 0.386036
LOGC_E, LOGC_F = 5.301883, 0.092819


def linear_to_logc(image: torch.Tensor) -> torch.Tensor:
    """Unity ``LinearToLogC``: ``c log10(max(a x + b, tiny)) + d``.

    Inputs below ``-b/a`` (≈ -0.0086, far out of gamut) all encode to the floor, as in Unity,
    where the ``max(…, 0)`` gives ``log10(0) = -inf``; the floor keeps it finite.

    Examples:
        >>> [round(v, 4) for v in linear_to_logc(torch.tensor([0.0, 0.18])).flatten().tolist()]
        [0.064, 0.391]
    """
    tiny = torch.finfo(image.dtype).tiny
    return LOGC_C * torch.log10((LOGC_A * image + LOGC_B).clamp_min(tiny)) + LOGC_D


def logc_to_linear(image: torch.Tensor) -> torch.Tensor:
    """Unity ``LogCToLinear``: ``(10^((x - d) / c) - b) / a``.

    Examples:
        >>> round(float(logc_to_linear(torch.tensor(0.391007))), 4)
        0.18
    """
    return (torch.pow(10.0, (image - LOGC_D) / LOGC_C) - LOGC_B) / LOGC_A


ACESCC_MIDGRAY = 0.4135884
"""ACEScc code value of 18% grey; Unity uses it as the contrast pivot in LogC too."""
ACESCC_MAX = 1.4679964
_HALF_MAX = 65504.0
_ACESCC_LOW_KNEE = (9.72 - 15.0) / 17.52


def aces_to_acescc(image: torch.Tensor) -> torch.Tensor:
    """ACES2065-1 -> ACEScc (S-2014-003 §4.4), input clamped to [0, 65504] as Unity does.

    Examples:
        >>> round(float(aces_to_acescc(torch.tensor(0.18))), 4)  # ACESCC_MIDGRAY
        0.4136
    """
    x = image.clamp(0.0, _HALF_MAX)
    low = (torch.log2(2.0**-16 + x * 0.5) + 9.72) / 17.52
    high = (torch.log2(x.clamp_min(2.0**-15)) + 9.72) / 17.52
    return torch.where(x < 2.0**-15, low, high)


def acescc_to_aces(image: torch.Tensor) -> torch.Tensor:
    """ACEScc -> ACES2065-1 (S-2014-003 §4.4); saturates at 65504 like Unity.

    Examples:
        >>> round(float(acescc_to_aces(torch.tensor(0.4135884))), 4)
        0.18
    """
    top = (torch.log2(torch.tensor(_HALF_MAX, dtype=torch.float64)).item() + 9.72) / 17.52
    x = image.clamp(max=top)
    value = torch.exp2(x * 17.52 - 9.72)
    return torch.where(x < _ACESCC_LOW_KNEE, (value - 2.0**-16) * 2.0, value)


def unity_to_aces(image: torch.Tensor) -> torch.Tensor:
    """Linear Rec.709 -> ACES2065-1 (AP0), Unity ``unity_to_ACES``.

    Examples:
        >>> # D65 white -> near the ACES white
        >>> [round(v, 4) for v in unity_to_aces(torch.ones(1, 3, 1, 1)).flatten().tolist()]
        [1.0, 1.0, 0.9998]
    """
    return convert(image, "srgb_to_ap0")


def aces_to_unity(image: torch.Tensor) -> torch.Tensor:
    """ACES2065-1 (AP0) -> linear Rec.709, Unity ``ACES_to_unity``.

    Examples:
        >>> [round(v, 4) for v in aces_to_unity(torch.ones(1, 3, 1, 1)).flatten().tolist()]
        [0.9999, 1.0, 1.0002]
    """
    return convert(image, "ap0_to_srgb")


def unity_to_acescg(image: torch.Tensor) -> torch.Tensor:
    """Linear Rec.709 -> ACEScg (AP1), Unity ``unity_to_ACEScg``.

    Examples:
        >>> [round(v, 4) for v in unity_to_acescg(torch.ones(1, 3, 1, 1)).flatten().tolist()]
        [1.0001, 1.0, 0.9998]
    """
    return convert(image, "srgb_to_ap1")


def acescg_to_unity(image: torch.Tensor) -> torch.Tensor:
    """ACEScg (AP1) -> linear Rec.709, Unity ``ACEScg_to_unity``.

    Examples:
        >>> [round(v, 4) for v in acescg_to_unity(torch.ones(1, 3, 1, 1)).flatten().tolist()]
        [0.9999, 1.0, 1.0002]
    """
    return convert(image, "ap1_to_srgb")


def aces_to_acescg(image: torch.Tensor) -> torch.Tensor:
    """ACES2065-1 (AP0) -> ACEScg (AP1).

    Examples:
        >>> [round(v, 4) for v in aces_to_acescg(torch.ones(1, 3, 1, 1)).flatten().tolist()]
        [1.0, 1.0, 1.0]
    """
    return convert(image, "ap0_to_ap1")


def acescg_to_aces(image: torch.Tensor) -> torch.Tensor:
    """ACEScg (AP1) -> ACES2065-1 (AP0).

    Examples:
        >>> [round(v, 4) for v in acescg_to_aces(torch.ones(1, 3, 1, 1)).flatten().tolist()]
        [1.0, 1.0, 1.0]
    """
    return convert(image, "ap1_to_ap0")


def linear_to_lms(image: torch.Tensor) -> torch.Tensor:
    """Linear Rec.709 -> LMS cone space (Unity ``LinearToLMS``).

    Examples:
        >>> [round(v, 4) for v in linear_to_lms(torch.ones(1, 3, 1, 1)).flatten().tolist()]
        [0.9493, 1.0354, 1.0874]
    """
    return convert(image, "linear_to_lms")


def lms_to_linear(image: torch.Tensor) -> torch.Tensor:
    """LMS cone space -> linear Rec.709 (Unity ``LMSToLinear``).

    Examples:
        >>> [round(v, 4) for v in lms_to_linear(linear_to_lms(torch.ones(1, 3, 1, 1))).flatten().tolist()]
        [1.0, 1.0, 1.0]
    """
    return convert(image, "lms_to_linear")


def rgb_to_hsv(image: torch.Tensor) -> torch.Tensor:
    """RGB -> HSV with hue in turns [0, 1), for non-negative RGB.

    The exact hexcone model (Smith 1978): ``V = max``, ``S = (max - min) / max``, hue from the
    dominant channel. Unlike Unity's ``RgbToHsv`` there is no ``1e-4`` bias, so HSV round trips are
    exact; at grey (undefined hue) and black (undefined saturation) hue and saturation are 0 and
    their gradients are finite.

    Examples:
        >>> orange = torch.tensor([1.0, 0.5, 0.0]).reshape(1, 3, 1, 1)
        >>> [round(v, 4) for v in rgb_to_hsv(orange).flatten().tolist()]
        [0.0833, 1.0, 1.0]
    """
    r, g, b = image.unbind(CHANNEL)
    value, argmax = image.max(dim=CHANNEL)
    delta = value - image.min(dim=CHANNEL).values
    chromatic = delta > 0
    safe_delta = torch.where(chromatic, delta, torch.ones_like(delta))
    hue_r = torch.remainder((g - b) / safe_delta, 6.0)
    hue_g = (b - r) / safe_delta + 2.0
    hue_b = (r - g) / safe_delta + 4.0
    hue = torch.where(argmax == 0, hue_r, torch.where(argmax == 1, hue_g, hue_b)) / 6.0
    hue = torch.where(chromatic, hue, torch.zeros_like(hue))
    lit = value > 0
    saturation = torch.where(lit, delta / torch.where(lit, value, torch.ones_like(value)), torch.zeros_like(value))
    return torch.stack((hue, saturation, value), dim=CHANNEL)


def hsv_to_rgb(image: torch.Tensor) -> torch.Tensor:
    """HSV (hue in turns) -> RGB: ``V * lerp(1, clamp(|frac(H + k) * 6 - 3| - 1, 0, 1), S)`` (Unity ``HsvToRgb``).

    Examples:
        >>> red = torch.tensor([0.0, 1.0, 2.0]).reshape(1, 3, 1, 1)  # hue 0, saturation 1, value 2
        >>> [round(v, 4) for v in hsv_to_rgb(red).flatten().tolist()]
        [2.0, 0.0, 0.0]
    """
    hue, saturation, value = (c.unsqueeze(CHANNEL) for c in image.unbind(CHANNEL))
    offsets = torch.tensor((0.0, 2.0 / 3.0, 1.0 / 3.0), dtype=image.dtype, device=image.device).reshape(3, 1, 1)
    ramp = (torch.abs(torch.frac(hue + offsets + 1.0) * 6.0 - 3.0) - 1.0).clamp(0.0, 1.0)
    return value * (1.0 + saturation * (ramp - 1.0))


REC709_CHROMATICITIES = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06), (0.3127, 0.3290))
"""Rec.709 / sRGB red, green, blue and D65 white as CIE xy."""

_BRADFORD = _m(((0.8951, 0.2664, -0.1614), (-0.7502, 1.7135, 0.0367), (0.0389, -0.0685, 1.0296)))


def _xy_to_xyz(x: float, y: float) -> torch.Tensor:
    return torch.tensor((x / y, 1.0, (1.0 - x - y) / y), dtype=torch.float64)


def rgb_to_xyz_matrix(chromaticities) -> torch.Tensor:
    """RGB -> XYZ for primaries and white given as ``((xr, yr), (xg, yg), (xb, yb), (xw, yw))`` (SMPTE RP 177).

    Examples:
        >>> # the Y row: Rec.709 luminance weights
        >>> [round(v, 4) for v in rgb_to_xyz_matrix(REC709_CHROMATICITIES)[1].tolist()]
        [0.2126, 0.7152, 0.0722]
    """
    primaries = torch.stack([_xy_to_xyz(x, y) for x, y in chromaticities[:3]], dim=1)
    scale = torch.linalg.solve(primaries, _xy_to_xyz(*chromaticities[3]))
    return primaries * scale


def bradford_adaptation(source_white, target_white) -> torch.Tensor:
    """XYZ -> XYZ von Kries adaptation in Bradford cone space from one white (xy) to another.

    Examples:
        >>> m = bradford_adaptation(AP0_CHROMATICITIES[3], REC709_CHROMATICITIES[3])
        >>> # the ACES white goes to the XYZ of D65
        >>> [round(v, 4) for v in (m @ rgb_to_xyz_matrix(AP0_CHROMATICITIES).sum(1)).tolist()]
        [0.9505, 1.0, 1.0891]
    """
    source, target = _BRADFORD @ _xy_to_xyz(*source_white), _BRADFORD @ _xy_to_xyz(*target_white)
    return torch.linalg.inv(_BRADFORD) @ torch.diag(target / source) @ _BRADFORD


def primaries_to_rec709_matrix(chromaticities) -> torch.Tensor:
    """float64 matrix taking linear RGB with the given primaries and white to linear Rec.709 (D65), Bradford-adapted.

    Examples:
        >>> m = primaries_to_rec709_matrix(REC2020_CHROMATICITIES)
        >>> [round(v, 4) for v in m.sum(1).flatten().tolist()]  # white stays white
        [1.0, 1.0, 1.0]
    """
    to_xyz = rgb_to_xyz_matrix(chromaticities)
    adapt = bradford_adaptation(chromaticities[3], REC709_CHROMATICITIES[3])
    return torch.linalg.inv(rgb_to_xyz_matrix(REC709_CHROMATICITIES)) @ adapt @ to_xyz


AP0_CHROMATICITIES = ((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.0770), (0.32168, 0.33767))
"""ACES AP0 (ACES2065-1) primaries and the ACES white (SMPTE ST 2065-1)."""

AP1_CHROMATICITIES = ((0.713, 0.293), (0.165, 0.830), (0.128, 0.044), (0.32168, 0.33767))
"""ACES AP1 (ACEScg, ACEScct) primaries and the ACES white (S-2014-004)."""

REC2020_CHROMATICITIES = ((0.708, 0.292), (0.170, 0.797), (0.131, 0.046), (0.3127, 0.3290))
"""ITU-R BT.2020 / BT.2100 primaries and D65 white."""

P3_D65_CHROMATICITIES = ((0.680, 0.320), (0.265, 0.690), (0.150, 0.060), (0.3127, 0.3290))
"""Display P3 (SMPTE EG 432-1 P3 primaries, D65 white)."""

MATRICES["rec709_to_rec2020"] = torch.linalg.inv(primaries_to_rec709_matrix(REC2020_CHROMATICITIES))
MATRICES["rec2020_to_rec709"] = primaries_to_rec709_matrix(REC2020_CHROMATICITIES)
MATRICES["rec709_to_p3"] = torch.linalg.inv(primaries_to_rec709_matrix(P3_D65_CHROMATICITIES))
MATRICES["p3_to_rec709"] = primaries_to_rec709_matrix(P3_D65_CHROMATICITIES)

# SMPTE ST 2084 constants.
PQ_M1, PQ_M2 = 2610.0 / 16384.0, 2523.0 / 4096.0 * 128.0
PQ_C1, PQ_C2, PQ_C3 = 3424.0 / 4096.0, 2413.0 / 4096.0 * 32.0, 2392.0 / 4096.0 * 32.0
PQ_PEAK = 10000.0
"""Luminance (cd/m²) of PQ code value 1."""


def linear_to_pq(image: torch.Tensor, reference: float = 100.0) -> torch.Tensor:
    """SMPTE ST 2084 inverse EOTF of ``image * reference`` cd/m², negatives clamped to 0.

    ``E' = ((c1 + c2 Y^m1) / (1 + c3 Y^m1))^m2`` with ``Y = image * reference / 10000``; the
    default ``reference`` puts 1.0 at 100 cd/m² (OpenColorIO's scene/display convention).

    Examples:
        >>> round(float(linear_to_pq(torch.tensor(1.0))), 4)  # 100 cd/m²
        0.5081
        >>> float(linear_to_pq(torch.tensor(10000.0), reference=1.0))
        1.0
    """
    y_m1 = safe_pow(image * (reference / PQ_PEAK), PQ_M1)
    return safe_pow((PQ_C1 + PQ_C2 * y_m1) / (1.0 + PQ_C3 * y_m1), PQ_M2)


def pq_to_linear(code: torch.Tensor, reference: float = 100.0) -> torch.Tensor:
    """SMPTE ST 2084 EOTF in units of ``reference`` cd/m²:
    ``10000 (max(E'^(1/m2) - c1, 0) / (c2 - c3 E'^(1/m2)))^(1/m1)``.

    Examples:
        >>> round(float(pq_to_linear(torch.tensor(0.5081))), 2)
        1.0
        >>> float(pq_to_linear(torch.tensor(1.0), reference=1.0))
        10000.0
    """
    e = safe_pow(code.clamp(max=1.0), 1.0 / PQ_M2)
    return PQ_PEAK / reference * safe_pow((e - PQ_C1).clamp_min(0.0) / (PQ_C2 - PQ_C3 * e), 1.0 / PQ_M1)


# ITU-R BT.2100 HLG constants.
HLG_A = 0.17883277
HLG_B = 1.0 - 4.0 * HLG_A
HLG_C = 0.5 - HLG_A * math.log(4.0 * HLG_A)


def hlg_oetf(image: torch.Tensor) -> torch.Tensor:
    """ITU-R BT.2100 HLG OETF of scene light ``E`` in ``[0, 1]``: ``sqrt(3 E)`` up to 1/12, else ``a ln(12 E - b) + c``.

    Examples:
        >>> [round(v, 4) for v in hlg_oetf(torch.tensor([1.0 / 12.0, 1.0])).tolist()]
        [0.5, 1.0]
    """
    low = safe_sqrt(3.0 * image)
    high = HLG_A * torch.log((12.0 * image).clamp_min(1.0) - HLG_B) + HLG_C
    return torch.where(image <= 1.0 / 12.0, low, high)


def hlg_inverse_oetf(code: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`hlg_oetf`: ``E'²/3`` up to 0.5, else ``(exp((E' - c) / a) + b) / 12``.

    Examples:
        >>> [round(v, 4) for v in hlg_inverse_oetf(torch.tensor([0.5, 1.0])).tolist()]
        [0.0833, 1.0]
    """
    low = code.clamp_min(0.0) ** 2 / 3.0
    high = (torch.exp((code.clamp(0.5, 2.0) - HLG_C) / HLG_A) + HLG_B) / 12.0
    return torch.where(code <= 0.5, low, high)


# ACEScct (S-2016-001): a linear toe below 2^-7, ACEScc's log segment above.
ACESCCT_CUT_LINEAR = 0.0078125
ACESCCT_CUT_LOG = 0.155251141552511
ACESCCT_A, ACESCCT_B = 10.5402377416545, 0.0729055341958355


def linear_to_acescct(image: torch.Tensor) -> torch.Tensor:
    """ACEScg (AP1) -> ACEScct: ``A x + B`` up to 2^-7, else ``(log2(x) + 9.72) / 17.52`` (S-2016-001).

    Examples:
        >>> [round(v, 4) for v in linear_to_acescct(torch.tensor([0.0, 0.18])).tolist()]
        [0.0729, 0.4136]
    """
    log = (torch.log2(image.clamp_min(ACESCCT_CUT_LINEAR)) + 9.72) / 17.52
    return torch.where(image <= ACESCCT_CUT_LINEAR, ACESCCT_A * image + ACESCCT_B, log)


def acescct_to_linear(code: torch.Tensor) -> torch.Tensor:
    """ACEScct -> ACEScg (AP1), the inverse of :func:`linear_to_acescct`, saturating at 65504 like ACEScc.

    Examples:
        >>> round(float(acescct_to_linear(torch.tensor(0.4135884))), 4)
        0.18
    """
    top = (math.log2(_HALF_MAX) + 9.72) / 17.52
    log = torch.exp2(code.clamp(ACESCCT_CUT_LOG, top) * 17.52 - 9.72)
    return torch.where(code <= ACESCCT_CUT_LOG, (code - ACESCCT_B) / ACESCCT_A, log)
