"""The ACES 1.x RRT's building blocks that every ACES-based rendering here shares.

Unity's ACES fit (:func:`~torchgrade.tonemap.aces`), Unreal's filmic curve and the ACES 1.0.3
reference (:func:`~torchgrade.tonemap.aces_reference`) all start with the RRT's glow and red
modifier and desaturate in AP1 before and after their tone scale; they differ in the hue weight
of the red modifier and in how they compute AP1 luminance. Constants: Unity ``ACES.hlsl``, from
the ACES 1.0.3 RRT and ODT (aces-dev ``rrt.ctl``).
"""

from __future__ import annotations

import math

import torch

from ...base.planes import apply_matrix, channel_max, channel_min, channel_sum
from ...color import (
    AP0_CHROMATICITIES,
    MATRICES,
    MATRIX_VALUES,
    primaries_to_rec709_matrix,
    safe_sqrt,
)
from ...runtime import affine, constant, scalar, values_of

__all__ = [
    "RRT_SAT_FACTOR",
    "ODT_SAT_FACTOR",
    "DIM_SURROUND_GAMMA",
    "smoothstep_hue_weight",
    "cubic_basis_hue_weight",
    "rrt_glow_and_red_modifier",
    "rrt_glow_and_red_modifier_planes",
    "ap1_desaturate",
    "ap1_dim_surround",
    "AP1_TO_REC709",
    "ap1_to_rec709",
    "REC709_TO_AP0",
    "rec709_to_aces",
    "UNITY_TINY",
    "ACES_TINY",
]

_RRT_GLOW_GAIN, _RRT_GLOW_MID = 0.05, 0.08
_RRT_RED_SCALE, _RRT_RED_PIVOT, _RRT_RED_HUE, _RRT_RED_WIDTH = 0.82, 0.03, 0.0, 135.0
RRT_SAT_FACTOR = 0.96
"""The RRT's desaturation towards AP1 luminance, before its tone scale."""
ODT_SAT_FACTOR = 0.93
"""The ODT's desaturation towards AP1 luminance, after the dim-surround step."""
DIM_SURROUND_GAMMA = 0.9811
"""The ODT's dark → dim surround compensation: ``Y → Y^0.9811``."""


UNITY_TINY, ACES_TINY = 1e-4, 1e-10
"""The floor of ``rgb_2_saturation``: Unity's half-precision ``TINYISH`` and the CTL's ``TINY``
(``ACESlib.RRT_Common.ctl``); they part on dark pixels with a negative component."""


REC709_TO_AP0 = torch.linalg.inv(primaries_to_rec709_matrix(AP0_CHROMATICITIES))
_REC709_TO_AP0_VALUES = values_of(REC709_TO_AP0)
"""Linear Rec.709 → ACES2065-1 from the primaries, Bradford D65 → ACES white, as OpenColorIO's configs.
Unity's rounded matrix differs by ~1e-4, which very out-of-gamut colours amplify to codes."""


def rec709_to_aces(image: torch.Tensor) -> torch.Tensor:
    """Linear Rec.709 → ACES2065-1 with :data:`REC709_TO_AP0`.

    Examples:
        >>> [round(v, 6) for v in rec709_to_aces(torch.ones(3, 1, 1, dtype=torch.float64)).flatten().tolist()]
        [1.0, 1.0, 1.0]
    """
    return apply_matrix(constant(_REC709_TO_AP0_VALUES, image), image)


def _saturation(high: torch.Tensor, low: torch.Tensor, tiny: float) -> torch.Tensor:
    """ACES ``rgb_2_saturation`` from the channels' max and min: ``(max(ma, tiny) - max(mi, tiny)) / max(ma, 1e-2)``."""
    return (high.clamp_min(tiny) - low.clamp_min(tiny)) / high.clamp_min(1e-2)


def _yc(r: torch.Tensor, g: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_yc``: ``(r + g + b + 1.75 sqrt(b(b-g) + g(g-r) + r(r-b))) / 3``."""
    chroma = safe_sqrt(torch.addcmul(torch.addcmul(b * (b - g), g, g - r), r, r - b))
    return torch.add(r + g + b, chroma, alpha=1.75) / 3.0


def _sigmoid_shaper(x: torch.Tensor) -> torch.Tensor:
    """ACES ``sigmoid_shaper``, a 0..1 sigmoid spanning -2..2: ``(1 + sign(x)(1 - t²)) / 2`` with
    ``t = max(1 - |x/2|, 0)``, written as ``1/2 + c (1/2 - |c|/8)`` with ``c = clamp(x, -2, 2)`` (the same curve:
    ``sign(x)(1 - t²) = c - c|c|/4``), without a ``sign`` (no ONNX Sign either: ``benchmarks/results/onnx_ops.md``).

    Examples:
        >>> _sigmoid_shaper(torch.tensor([-3.0, -1.0, 0.0, 1.0, 2.0])).tolist()
        [0.0, 0.125, 0.5, 0.875, 1.0]
    """
    c = x.clamp(-2.0, 2.0)
    return 0.5 + c * affine(torch.abs(c), -0.125, 0.5)


def _glow(yc: torch.Tensor, gain: torch.Tensor, mid: float) -> torch.Tensor:
    """ACES ``glow_fwd``: full gain below 2/3·mid, none above 2·mid, ``gain (mid / yc - 1/2)`` between: with ``yc``
    clamped to that ramp, ``gain (mid / yc - 1/2)`` is ``gain`` (to float rounding) below it and exactly 0 above it,
    without selects.

    Examples:
        >>> [round(v, 6) for v in _glow(torch.tensor([0.0, 0.08, 1.0]), torch.tensor(0.05), 0.08).tolist()]
        [0.05, 0.025, 0.0]
    """
    return torch.div(scalar(mid, yc), yc.clamp(2.0 / 3.0 * mid, 2.0 * mid)).sub(0.5).mul(gain)


def smoothstep_hue_weight(centered_hue: torch.Tensor) -> torch.Tensor:
    """The red modifier's hue weight as Unity and Unreal approximate it: ``smoothstep(0, 1, 1 - |2h / 135|)²``, with
    ``smoothstep(0, 1, t) = t²(3 - 2t)`` on ``t`` clamped to [0, 1].

    Examples:
        >>> [round(w, 12) for w in smoothstep_hue_weight(torch.tensor([0.0, 67.5])).tolist()]  # 0 to float rounding
        [1.0, 0.0]
    """
    t = affine(torch.abs(centered_hue), -2.0 / _RRT_RED_WIDTH, 1.0).clamp(0.0, 1.0)
    return (t * t * affine(t, -2.0, 3.0)) ** 2


def cubic_basis_hue_weight(centered_hue: torch.Tensor) -> torch.Tensor:
    """ACES ``cubic_basis_shaper(h, 135)``: the uniform cubic B-spline on knots ``-w/2 .. w/2``, times 3/2.

    With ``u = 4 |h| / w`` (knot intervals from the centre): ``(4 - 6u² + 3u³) / 6`` for ``u < 1``,
    ``(2 - u)³ / 6`` for ``1 ≤ u < 2``, 0 beyond; the 3/2 makes the peak 1.

    Examples:
        >>> cubic_basis_hue_weight(torch.tensor([0.0, 67.5])).tolist()
        [1.0, 0.0]
    """
    u = torch.abs(centered_hue) * (4.0 / _RRT_RED_WIDTH)
    inner = (4.0 - 6.0 * u * u + 3.0 * u * u * u) / 6.0
    outer = (2.0 - u).clamp_min(0.0) ** 3 / 6.0
    return 1.5 * torch.where(u < 1.0, inner, outer)


def rrt_glow_and_red_modifier(aces: torch.Tensor, hue_weight, tiny: float = UNITY_TINY) -> torch.Tensor:
    """The ACES RRT's first two modules on ACES2065-1 (RRT 1.0.3, ``rrt.ctl``), computed on its planes
    (:func:`rrt_glow_and_red_modifier_planes`) and joined.

    Glow: ``aces · (1 + glow_fwd(yc, 0.05 · sigmoid_shaper((s - 0.4) / 0.2), 0.08))`` with ``s`` the
    saturation; red modifier: ``r += w(h) · s · (0.03 - r) · (1 - 0.82)`` with ``h`` the hue centred on
    red (degrees) and ``hue_weight`` the function ``w``; ``tiny`` floors the saturation's terms.

    Examples:
        >>> grey = torch.full((3, 1, 1), 0.18)
        >>> torch.equal(rrt_glow_and_red_modifier(grey, smoothstep_hue_weight), grey)  # no saturation: no glow
        True
    """
    return torch.cat(rrt_glow_and_red_modifier_planes(aces.split(1, dim=-3), hue_weight, tiny), dim=-3)


def rrt_glow_and_red_modifier_planes(planes, hue_weight, tiny: float = UNITY_TINY) -> tuple:
    """:func:`rrt_glow_and_red_modifier` on the three planes of ACES2065-1 (of one split), returned as three planes of the
    same shape.

    Saturation, ``yc`` and hue each read the three planes: split once, no broadcast product of the frame by a plane (in
    ONNX each split is a node, and such a product costs more than the 3 products of planes here). Channel max and min
    are maxima and minima of the planes (no reduction over channels, ``benchmarks/results/onnx_ops.md``), and the hue
    is its distance from red (:func:`_red_hue_distance`), read before the glow (which scales the three channels alike,
    by a gain of at least 1: the same hue).
    """
    if isinstance(planes, torch.Tensor):
        raise TypeError("rrt_glow_and_red_modifier_planes takes an image's three planes as a tuple (image.split(1, dim=-3))")
    r, g, b = planes
    saturation = _saturation(channel_max((r, g, b)), channel_min((r, g, b)), tiny)
    s = _sigmoid_shaper(affine(saturation, 5.0, -2.0))  # (s - 0.4) / 0.2
    gain = 1.0 + _glow(_yc(r, g, b), _RRT_GLOW_GAIN * s, _RRT_GLOW_MID)
    weight = hue_weight(_red_hue_distance(r, g, b)) * saturation
    r, g, b = r * gain, g * gain, b * gain
    return torch.addcmul(r, weight, _RRT_RED_PIVOT - r, value=1.0 - _RRT_RED_SCALE), g, b


def _red_hue_distance(r: torch.Tensor, g: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``|atan2(y, x)|`` in degrees, ``y = sqrt(3)(g - b)``, ``x = 2r - g - b``: the red-centred hue's distance from red,
    all the (symmetric) hue weights read, as ``atan((|y| + max(-x, 0)) / max(x, 1e-30))``.

    ``atan2`` exports as an Atan and two selects, and a hue's guards and wraps add five more (a select's cost:
    ``benchmarks/results/onnx_ops.md``); the weights read only the distance. For ``x > 0`` this is ``atan(|y| / x)``;
    for ``x < 0`` the ratio is ``(|y| + |x|) / 1e-30``, so 90° (no weight), as every hue past ±90° has; a neutral
    pixel gets 0°, as ``atan2(0, 0)``. An ``x`` that is not 0 is a float32 step of the pixel's largest channel or
    more, so ``1e-30`` only moves hues of pixels darker than the saturation's floor, where the weight is unused.
    Written with ``-x = g + b - 2r`` and the ratio's sign moved into the degrees: ten operations.
    """
    negated = torch.add(g + b, r, alpha=-2.0)
    ratio = torch.add(torch.relu(negated), torch.abs(g - b), alpha=3.0**0.5) / negated.clamp_max(-1e-30)
    return torch.atan(ratio) * (-180.0 / math.pi)


def _ap1_y(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``AP1_RGB2Y``: luminance of ACEScg, the middle row of the AP1 → XYZ matrix (full precision)."""
    return channel_sum(rgb, MATRIX_VALUES["ap1_to_xyz"][1])


def ap1_desaturate(rgb: torch.Tensor, factor: float) -> torch.Tensor:
    """ACES ``calc_sat_adjust_matrix(factor, AP1_RGB2Y)``: ``Y + factor (rgb - Y)``, ``Y`` the AP1 luminance.

    Examples:
        >>> grey = torch.full((3, 1, 1), 0.5, dtype=torch.float64)
        >>> torch.allclose(ap1_desaturate(grey, RRT_SAT_FACTOR), grey)
        True
    """
    y = _ap1_y(rgb)
    return y + factor * (rgb - y)


def ap1_dim_surround(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``darkSurround_to_dimSurround``: ``Y → Y^0.9811`` keeping xy, i.e. ``rgb · Y^(0.9811 - 1)``.

    ``Y`` is AP1 luminance floored at 1e-10, as OpenColorIO's ``ACES_DarkToDim10``; it leaves
    near-black pixels where they are.

    Examples:
        >>> ap1_dim_surround(torch.ones(3, 1, 1, dtype=torch.float64)).flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    return rgb * _ap1_y(rgb).clamp_min(1e-10) ** (DIM_SURROUND_GAMMA - 1.0)


AP1_TO_REC709 = MATRICES["xyz_to_rec709"] @ MATRICES["d60_to_d65"] @ MATRICES["ap1_to_xyz"]
_AP1_TO_REC709_VALUES = values_of(AP1_TO_REC709)
"""The ODTs' last step, AP1 → XYZ → Bradford D60 → D65 → linear Rec.709, as one float64 matrix."""


def ap1_to_rec709(rgb: torch.Tensor) -> torch.Tensor:
    """The ODTs' last step: :data:`AP1_TO_REC709`, one matrix per pixel.

    Examples:
        >>> ap1_to_rec709(torch.zeros(3, 1, 1)).flatten().tolist()
        [0.0, 0.0, 0.0]
    """
    return apply_matrix(constant(_AP1_TO_REC709_VALUES, rgb), rgb)
