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
from ...runtime import affine, constant, scalar, values_of, where
from ...runtime.variants import formula

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


def _rgb_saturation(rgb: torch.Tensor, tiny: float) -> torch.Tensor:
    """ACES ``rgb_2_saturation`` of an image (see :func:`_saturation`)."""
    return _saturation(channel_max(rgb), channel_min(rgb), tiny)


def _saturation(high: torch.Tensor, low: torch.Tensor, tiny: float) -> torch.Tensor:
    """ACES ``rgb_2_saturation`` from the channels' max and min: ``(max(ma, tiny) - max(mi, tiny)) / max(ma, 1e-2)``."""
    return (high.clamp_min(tiny) - low.clamp_min(tiny)) / high.clamp_min(1e-2)


def _rgb_yc(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_yc`` of an image (see :func:`_yc`)."""
    return _yc(*rgb.split(1, dim=-3))


def _yc(r: torch.Tensor, g: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_yc``: ``(r + g + b + 1.75 sqrt(b(b-g) + g(g-r) + r(r-b))) / 3``."""
    chroma = safe_sqrt(torch.addcmul(torch.addcmul(b * (b - g), g, g - r), r, r - b))
    return torch.add(r + g + b, chroma, alpha=1.75) / 3.0


def _rgb_hue_degrees(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_hue`` in [0, 360): ``atan2(sqrt(3)(g - b), 2r - g - b)``; 0 for neutrals.

    Where ``x² + y²`` is below the dtype's smallest normal the hue passes no gradient: atan2's derivative,
    ``(x, -y) / (x² + y²)``, is then 0/0 or beyond the dtype (a float32 pixel of 2.3e-23 gave NaN on every channel).
    Only pixels whose saturation is 0 get there: their channels differ by less than a step of a channel above the
    saturation's floor (a float32 step of 1e-10 is 6.9e-18, the hue's ``sqrt(tiny)`` 1.1e-19), and the red modifier
    multiplies the hue's weight by that saturation. The values stay ``atan2``'s.
    """
    r, g, b = rgb.split(1, dim=-3)
    y = 3.0**0.5 * (g - b)
    x = 2.0 * r - g - b
    x = where((x == 0) & (y == 0), 1.0, x)  # neutral: 0°
    flat = torch.addcmul(x * x, y, y) <= torch.finfo(x.dtype).tiny
    hue = torch.atan2(torch.where(flat, y.detach(), y), torch.where(flat, x.detach(), x)) * (180.0 / math.pi)  # rad2deg has no ONNX export
    return torch.where(hue < 0, hue + 360.0, hue)


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


@formula
def _glow(yc: torch.Tensor, gain: torch.Tensor, mid: float) -> torch.Tensor:
    """ACES ``glow_fwd``: full gain below 2/3·mid, none above 2·mid, ``gain (mid / yc - 1/2)`` between.

    Examples:
        >>> [round(v, 6) for v in _glow(torch.tensor([0.0, 0.08, 1.0]), torch.tensor(0.05), 0.08).tolist()]
        [0.05, 0.025, 0.0]
    """
    between = gain * (mid / yc.clamp_min(2.0 / 3.0 * mid) - 0.5)
    return where(yc <= 2.0 / 3.0 * mid, gain, where(yc >= 2.0 * mid, 0.0, between))


@_glow.variant("untracked")
@_glow.variant("export")
def _glow_clamped(yc: torch.Tensor, gain: torch.Tensor, mid: float) -> torch.Tensor:
    """``yc`` clamped to the ramp gives ``gain`` (to float rounding) below it and exactly 0 above it, without selects."""
    return torch.div(scalar(mid, yc), yc.clamp(2.0 / 3.0 * mid, 2.0 * mid)).sub_(0.5).mul_(gain)


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


@formula
def rrt_glow_and_red_modifier(aces: torch.Tensor, hue_weight, tiny: float = UNITY_TINY) -> torch.Tensor:
    """The ACES RRT's first two modules on ACES2065-1 (RRT 1.0.3, ``rrt.ctl``).

    Glow: ``aces · (1 + glow_fwd(yc, 0.05 · sigmoid_shaper((s - 0.4) / 0.2), 0.08))`` with ``s`` the
    saturation; red modifier: ``r += w(h) · s · (0.03 - r) · (1 - 0.82)`` with ``h`` the hue centred on
    red (degrees) and ``hue_weight`` the function ``w``; ``tiny`` floors the saturation's terms.

    Examples:
        >>> grey = torch.full((3, 1, 1), 0.18)
        >>> torch.equal(rrt_glow_and_red_modifier(grey, smoothstep_hue_weight), grey)  # no saturation: no glow
        True
    """
    _, red, green_blue, weight = _glowed_and_red_terms(aces, hue_weight, tiny)
    return torch.cat((torch.addcmul(red, weight, _RRT_RED_PIVOT - red, value=1.0 - _RRT_RED_SCALE), green_blue), dim=-3)


@rrt_glow_and_red_modifier.variant("untracked")
def _rrt_glow_and_red_modifier_in_place(aces: torch.Tensor, hue_weight, tiny: float = UNITY_TINY) -> torch.Tensor:
    """The red modifier in place on the glow's product (made here), which it returns."""
    glowed, red, _, weight = _glowed_and_red_terms(aces, hue_weight, tiny)
    red.addcmul_(weight, _RRT_RED_PIVOT - red, value=1.0 - _RRT_RED_SCALE)
    return glowed


@rrt_glow_and_red_modifier.variant("export")
def _rrt_glow_and_red_modifier_exported(aces: torch.Tensor, hue_weight, tiny: float = UNITY_TINY) -> torch.Tensor:
    """On planes (:func:`rrt_glow_and_red_modifier_planes`), joined."""
    return torch.cat(rrt_glow_and_red_modifier_planes(aces.split(1, dim=-3), hue_weight, tiny), dim=-3)


def _glowed_and_red_terms(aces: torch.Tensor, hue_weight, tiny: float) -> tuple:
    """The glow applied, its red and its green and blue (views of it), and the red modifier's weight ``w(h) s``."""
    saturation = _rgb_saturation(aces, tiny)
    s = _sigmoid_shaper(affine(saturation, 5.0, -2.0))  # (s - 0.4) / 0.2
    glowed = torch.addcmul(aces, aces, _glow(_rgb_yc(aces), _RRT_GLOW_GAIN * s, _RRT_GLOW_MID))
    red, green_blue = glowed.split((1, 2), dim=-3)
    return glowed, red, green_blue, hue_weight(_red_centered_hue(glowed)) * saturation


def rrt_glow_and_red_modifier_planes(planes, hue_weight, tiny: float = UNITY_TINY) -> tuple:
    """The exported and compiled form of :func:`rrt_glow_and_red_modifier`: the same modules on the three planes of
    ACES2065-1 (exported, of one ``Split``), returned as three planes of the same shape.

    Saturation, ``yc`` and hue each split the image in the eager form, and the glow scales it by a plane; in ONNX each
    split is a node, and that broadcast product costs more than the 3 products of planes here. Channel max and min are
    Max and Min of the planes (no reduction over channels, ``benchmarks/results/onnx_ops.md``), and the hue is its distance from red
    (:func:`_red_hue_distance`).
    """
    if isinstance(planes, torch.Tensor):
        raise TypeError("rrt_glow_and_red_modifier_planes takes an image's three planes as a tuple (image.split(1, dim=-3))")
    r, g, b = planes
    saturation = _saturation(channel_max((r, g, b)), channel_min((r, g, b)), tiny)
    s = _sigmoid_shaper(affine(saturation, 5.0, -2.0))  # (s - 0.4) / 0.2
    gain = 1.0 + _glow(_yc(r, g, b), _RRT_GLOW_GAIN * s, _RRT_GLOW_MID)
    r, g, b = r * gain, g * gain, b * gain
    change = hue_weight(_red_hue_distance(r, g, b)) * saturation * (_RRT_RED_PIVOT - r) * (1.0 - _RRT_RED_SCALE)
    return r + change, g, b


@formula
def _red_centered_hue(rgb: torch.Tensor) -> torch.Tensor:
    """The hue in degrees relative to red's (``_RRT_RED_HUE``, 0°), in (-180, 180]: ``hue - 0`` wrapped.

    Eager, that is ``atan2`` itself, which also gives 0 for neutrals: the hue's shift into [0, 360) and
    back is skipped (it moved hues below 0° by float rounding, 3e-5° at most).
    """
    centered = _rgb_hue_degrees(rgb) - _RRT_RED_HUE
    return torch.where(centered < -180.0, centered + 360.0, torch.where(centered > 180.0, centered - 360.0, centered))


@_red_centered_hue.variant("untracked")
def _red_centered_hue_of_atan2(rgb: torch.Tensor) -> torch.Tensor:
    """``atan2`` itself, in place on its temporaries."""
    r, g, b = rgb.split(1, dim=-3)
    return torch.atan2((g - b).mul_(3.0**0.5), (2.0 * r).sub_(g).sub_(b)).mul_(180.0 / math.pi)


def _red_hue_distance(r: torch.Tensor, g: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``|atan2(y, x)|`` in degrees, ``y = sqrt(3)(g - b)``, ``x = 2r - g - b``: the red-centred hue's distance from red,
    all the (symmetric) hue weights read, as ``atan((|y| + max(-x, 0)) / max(x, 1e-30))``.

    The export form of :func:`_red_centered_hue`: ``atan2`` exports as an Atan and two selects, and the hue's guards
    and wraps add five more (a select's cost: ``benchmarks/results/onnx_ops.md``). For ``x > 0`` this is ``atan(|y| / x)``;
    for ``x < 0`` the ratio is ``(|y| + |x|) / 1e-30``, so 90° (no weight), as every hue past ±90° has; a neutral
    pixel gets 0°, as ``atan2(0, 0)``. An ``x`` that is not 0 is a float32 step of the pixel's largest channel or
    more, so ``1e-30`` only moves hues of pixels darker than the saturation's floor, where the weight is unused.
    """
    y = torch.abs(g - b) * 3.0**0.5
    x = 2.0 * r - g - b
    return torch.atan((y + torch.relu(-x)) / x.clamp_min(1e-30)) * (180.0 / math.pi)


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
