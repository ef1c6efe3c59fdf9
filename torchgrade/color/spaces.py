"""Colour spaces as matrices on ``(..., 3, H, W)`` tensors: Rec.709, ACES AP0/AP1, LMS, XYZ, Rec.2020,
Display P3; luminance weights; primaries from CIE xy chromaticities and Bradford adaptation.

Constants are Unity's (``Color.hlsl``, ``ACES.hlsl``) where Unity defines them, else the standards'
(ITU-R BT.709 and BT.2020, SMPTE EG 432-1, Academy S-2008-001).
"""

from __future__ import annotations

import torch

from ..base.planes import apply_matrix, channel_sum
from ..runtime import constant, values_of

__all__ = [
    "matrix", "convert", "luminance", "unity_to_aces", "aces_to_unity", "unity_to_acescg", "acescg_to_unity", "aces_to_acescg", "acescg_to_aces", "linear_to_lms", "lms_to_linear", "rgb_to_xyz_matrix", "bradford_adaptation", "primaries_to_rec709_matrix", "CHANNEL", "REC709_LUMINANCE", "AP1_LUMINANCE", "MATRICES", "MATRIX_VALUES", "REC709_CHROMATICITIES", "AP0_CHROMATICITIES", "AP1_CHROMATICITIES", "REC2020_CHROMATICITIES", "P3_D65_CHROMATICITIES",
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
    """One of :data:`MATRICES` in ``like``'s dtype and device: a copy, which the caller may change.

    Examples:
        >>> m = matrix("srgb_to_ap1", torch.zeros(1, dtype=torch.float64))
        >>> m.shape, m.dtype
        (torch.Size([3, 3]), torch.float64)
    """
    return shared_matrix(name, like).clone()


def shared_matrix(name: str, like: torch.Tensor) -> torch.Tensor:
    """:func:`matrix` as the device constant every conversion shares (:func:`~torchgrade.runtime.constant`): made
    once per dtype and device, never to be modified in place.

    Examples:
        >>> shared_matrix("ap0_to_ap1", torch.zeros(1)) is shared_matrix("ap0_to_ap1", torch.zeros(1))
        True
    """
    return constant(MATRIX_VALUES[name], like)


def convert(image: torch.Tensor, name: str) -> torch.Tensor:
    """Apply the named 3x3 matrix of :data:`MATRICES` to every pixel.

    Examples:
        >>> [round(v, 4) for v in convert(torch.ones(1, 3, 1, 1), "ap0_to_ap1").flatten().tolist()]
        [1.0, 1.0, 1.0]
    """
    return apply_matrix(shared_matrix(name, image), image)


def luminance(image: torch.Tensor, weights: str = "rec709") -> torch.Tensor:
    """Relative luminance ``Y = w · rgb`` as ``(..., 1, H, W)``; ``weights`` is ``"rec709"`` or ``"ap1"``.

    Examples:
        >>> luminance(torch.ones(1, 3, 2, 2)).shape
        torch.Size([1, 1, 2, 2])
        >>> round(float(luminance(torch.ones(1, 3, 1, 1))), 4)
        1.0
    """
    return channel_sum(image, {"rec709": REC709_LUMINANCE, "ap1": AP1_LUMINANCE}[weights])


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

MATRIX_VALUES = {name: values_of(m) for name, m in MATRICES.items()}
""":data:`MATRICES` as tuples of Python floats: what :func:`matrix` makes device constants of."""
