"""Tone mapping: scene-referred linear Rec.709 in, display-referred linear Rec.709 in [0, 1] out.

Every curve clamps its input to ``[0, limit]`` first: negative (out-of-gamut) values map to black
and, as in the source documents, values above 60 are treated as 60 (beyond it every curve here is
within 1/255 of its asymptote, and half-precision evaluation stays finite). The output is clamped
to [0, 1]; sRGB encoding is a separate step (:func:`torchgrade.color.linear_to_srgb`).
"""

from __future__ import annotations

import contextvars
import inspect
import math

import torch
from torch import nn

from .color import convert, luminance, matrix, safe_pow, safe_sqrt, unity_to_aces
from .core import HALF_MAX, Param, apply_matrix, check_image, check_range, sanitize, scalar_param, working_dtype, to_input_dtype
from .params import ParamModule

TONEMAP_INPUT_LIMIT = 60.0
"""Inputs are clamped to this before tone mapping (Catlike Coding, HDR §3.3: 'a limit of 60')."""


def _limited(image: torch.Tensor, limit=TONEMAP_INPUT_LIMIT) -> torch.Tensor:
    return torch.minimum(image.clamp_min(0.0), torch.as_tensor(limit, dtype=image.dtype, device=image.device))


_CLIP = contextvars.ContextVar("tonemap_clip", default=True)
"""Whether :func:`_display` clips to [0, 1]; ``tonemap(..., clip=False)`` turns it off for one call."""


def _display(image: torch.Tensor) -> torch.Tensor:
    return image.clamp(0.0, 1.0) if _CLIP.get() else image


def reinhard(image: torch.Tensor) -> torch.Tensor:
    """Per-channel Reinhard: ``c / (1 + c)`` with ``c = clamp(x, 0, 60)`` (Reinhard et al. 2002, eq. 3)."""
    c = _limited(image)
    return _display(c / (1.0 + c))


def reinhard_extended(image: torch.Tensor, white_point: Param = 4.0) -> torch.Tensor:
    """Per-channel Reinhard with a white point ``w``: ``c (1 + c / w²) / (1 + c)`` (Reinhard 2002, eq. 4).

    ``c`` is clamped to ``[0, w]``: the curve reaches 1 at ``c = w`` and the display clips beyond it.
    """
    w = scalar_param(white_point, image, "white_point")
    c = _limited(image, w)
    return _display(c * (1.0 + c / (w * w)) / (1.0 + c))


def reinhard_luminance(image: torch.Tensor, white_point: Param = 4.0) -> torch.Tensor:
    """Extended Reinhard on luminance, colour scaled to the new luminance (004 notes, ``reinhard_extended_luminance``).

    ``L' = L (1 + L / w²) / (1 + L)`` and ``rgb' = rgb · L' / L``; the ratio ``L'/L = (1 + L/w²) / (1 + L)``
    needs no division by ``L``, so black pixels stay finite. ``L`` is clamped at 0.
    """
    w = scalar_param(white_point, image, "white_point")
    lum = luminance(image).clamp_min(0.0)
    ratio = (1.0 + lum / (w * w)) / (1.0 + lum)
    return _display(image * ratio)


def _hable_curve(x: torch.Tensor, a, b, c, d, e, f) -> torch.Tensor:
    """Hable's filmic curve ``t(x) = (x (a x + c b) + d e) / (x (a x + b) + d f) - e / f``."""
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


_NEUTRAL = dict(a=0.2, b=0.29, c=0.24, d=0.272, e=0.02, f=0.3)
_NEUTRAL_WHITE_LEVEL = 5.3


def neutral(image: torch.Tensor) -> torch.Tensor:
    """Unity's Neutral tone mapper (``NeutralTonemap``, Color.hlsl): ``t(x·s)·s`` with ``s = 1 / t(5.3)``.

    ``t`` is Hable's curve with a=0.2, b=0.29, c=0.24, d=0.272, e=0.02, f=0.3; the effective white
    point, where the output reaches 1, is ``5.3 / s ≈ 4.035``.
    """
    white = torch.tensor(_NEUTRAL_WHITE_LEVEL, dtype=image.dtype, device=image.device)
    scale = 1.0 / _hable_curve(white, **_NEUTRAL)
    return _display(_hable_curve(_limited(image) * scale, **_NEUTRAL) * scale)


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
) -> torch.Tensor:
    """Hable's filmic curve with its six parameters exposed: ``t(x · bias) / t(w)`` (Hable 2010, slides 142-143).

    ``t`` is :func:`_hable_curve` with A = shoulder strength, B = linear strength, C = linear angle,
    D = toe strength, E = toe numerator, F = toe denominator (HDRP's and Unreal's "custom" filmic
    controls). The defaults are Uncharted 2's (A=0.15, B=0.50, C=0.10, D=0.20, E=0.02, F=0.30,
    W=11.2, bias 2), so ``filmic`` with defaults is :func:`hable`. Since
    ``t(x) = x (A (F - E) x + B (C F - E)) / (F (x (A x + B) + D F))``, the curve rises from 0 when
    ``E ≤ F`` and ``E ≤ C F``.
    """
    names = ("shoulder_strength", "linear_strength", "linear_angle", "toe_strength", "toe_numerator", "toe_denominator")
    values = (shoulder_strength, linear_strength, linear_angle, toe_strength, toe_numerator, toe_denominator)
    k = [scalar_param(value, image, name) for value, name in zip(values, names)]
    bias = scalar_param(exposure_bias, image, "exposure_bias")
    w = scalar_param(white_point, image, "white_point")
    return _display(_hable_curve(_limited(image) * bias, *k) / _hable_curve(w, *k))


def hable(image: torch.Tensor, exposure_bias: Param = 2.0, white_point: Param = 11.2) -> torch.Tensor:
    """Uncharted 2 filmic curve: ``t(x · bias) / t(w)`` (Hable 2010, slides 142-143; HDR §3.4).

    Constants A=0.15, B=0.50, C=0.10, D=0.20, E=0.02, F=0.30, exposure bias 2 and white point 11.2:
    :func:`filmic` with its default curve.
    """
    return filmic(image, exposure_bias=exposure_bias, white_point=white_point)


# ACES constants (Unity ACES.hlsl, from the ACES 1.0.3 RRT and ODT).
_RRT_GLOW_GAIN, _RRT_GLOW_MID = 0.05, 0.08
_RRT_RED_SCALE, _RRT_RED_PIVOT, _RRT_RED_HUE, _RRT_RED_WIDTH = 0.82, 0.03, 0.0, 135.0
_RRT_SAT_FACTOR, _ODT_SAT_FACTOR = 0.96, 0.93
_DIM_SURROUND_GAMMA = 0.9811
# Luminance fit of RRT 1.0.3 + ODT RGBmonitor_100nits_dim (Unity AcesTonemap; RMSE 0.0013).
_ACES_FIT = dict(a=2.785085, b=0.107772, c=2.936045, d=0.887122, e=0.806889)


def _rgb_saturation(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_saturation``: ``(max(ma, 1e-4) - max(mi, 1e-4)) / max(ma, 1e-2)``."""
    high = rgb.amax(dim=-3, keepdim=True)
    low = rgb.amin(dim=-3, keepdim=True)
    return (high.clamp_min(1e-4) - low.clamp_min(1e-4)) / high.clamp_min(1e-2)


def _rgb_yc(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_yc``: ``(r + g + b + 1.75 sqrt(b(b-g) + g(g-r) + r(r-b))) / 3``."""
    r, g, b = rgb.split(1, dim=-3)
    chroma = safe_sqrt(b * (b - g) + g * (g - r) + r * (r - b))
    return (r + g + b + 1.75 * chroma) / 3.0


def _rgb_hue_degrees(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_hue`` in [0, 360): ``atan2(sqrt(3)(g - b), 2r - g - b)``; 0 for neutrals."""
    r, g, b = rgb.split(1, dim=-3)
    y = 3.0**0.5 * (g - b)
    x = 2.0 * r - g - b
    neutral_pixel = (x == 0) & (y == 0)
    hue = torch.atan2(y, torch.where(neutral_pixel, torch.ones_like(x), x)) * (180.0 / math.pi)  # rad2deg has no ONNX export
    hue = torch.where(neutral_pixel, torch.zeros_like(hue), hue)
    return torch.where(hue < 0, hue + 360.0, hue)


def _sigmoid_shaper(x: torch.Tensor) -> torch.Tensor:
    """ACES ``sigmoid_shaper``: a 0..1 sigmoid spanning -2..2."""
    t = (1.0 - torch.abs(x / 2.0)).clamp_min(0.0)
    return (1.0 + torch.sign(x) * (1.0 - t * t)) / 2.0


def _glow(yc: torch.Tensor, gain: torch.Tensor, mid: float) -> torch.Tensor:
    """ACES ``glow_fwd``: full gain below 2/3·mid, none above 2·mid, ``gain (mid / yc - 1/2)`` between."""
    between = gain * (mid / yc.clamp_min(2.0 / 3.0 * mid) - 0.5)
    return torch.where(yc <= 2.0 / 3.0 * mid, gain, torch.where(yc >= 2.0 * mid, torch.zeros_like(gain), between))


def _smoothstep(edge0, edge1, x: torch.Tensor) -> torch.Tensor:
    t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _smoothstep_hue_weight(centered_hue: torch.Tensor) -> torch.Tensor:
    """The red modifier's hue weight as Unity and Unreal approximate it: ``smoothstep(0, 1, 1 - |2h / 135|)²``."""
    return _smoothstep(0.0, 1.0, 1.0 - torch.abs(2.0 * centered_hue / _RRT_RED_WIDTH)) ** 2


def _cubic_basis_hue_weight(centered_hue: torch.Tensor) -> torch.Tensor:
    """ACES ``cubic_basis_shaper(h, 135)``: the uniform cubic B-spline on knots ``-w/2 .. w/2``, times 3/2.

    With ``u = 4 |h| / w`` (knot intervals from the centre): ``(4 - 6u² + 3u³) / 6`` for ``u < 1``,
    ``(2 - u)³ / 6`` for ``1 ≤ u < 2``, 0 beyond; the 3/2 makes the peak 1.
    """
    u = torch.abs(centered_hue) * (4.0 / _RRT_RED_WIDTH)
    inner = (4.0 - 6.0 * u * u + 3.0 * u * u * u) / 6.0
    outer = (2.0 - u).clamp_min(0.0) ** 3 / 6.0
    return 1.5 * torch.where(u < 1.0, inner, outer)


def _rrt_glow_and_red_modifier(aces: torch.Tensor, hue_weight) -> torch.Tensor:
    """The ACES RRT's first two modules on ACES2065-1 (RRT 1.0.3, ``rrt.ctl``).

    Glow: ``aces · (1 + glow_fwd(yc, 0.05 · sigmoid_shaper((s - 0.4) / 0.2), 0.08))`` with ``s`` the
    saturation; red modifier: ``r += w(h) · s · (0.03 - r) · (1 - 0.82)`` with ``h`` the hue centred on
    red (degrees) and ``hue_weight`` the function ``w``.
    """
    saturation = _rgb_saturation(aces)
    s = _sigmoid_shaper((saturation - 0.4) / 0.2)
    aces = aces * (1.0 + _glow(_rgb_yc(aces), _RRT_GLOW_GAIN * s, _RRT_GLOW_MID))

    centered = _rgb_hue_degrees(aces) - _RRT_RED_HUE
    centered = torch.where(centered < -180.0, centered + 360.0, torch.where(centered > 180.0, centered - 360.0, centered))
    red, green_blue = aces.split((1, 2), dim=-3)
    red = red + hue_weight(centered) * saturation * (_RRT_RED_PIVOT - red) * (1.0 - _RRT_RED_SCALE)
    return torch.cat((red, green_blue), dim=-3)


def _lerp_to_luminance(rgb: torch.Tensor, factor: float) -> torch.Tensor:
    """``lerp(Y, rgb, factor)`` with AP1 luminance (the RRT/ODT desaturation)."""
    y = luminance(rgb, "ap1")
    return y + factor * (rgb - y)


def _dark_to_dim_surround(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``darkSurround_to_dimSurround``: ``Y → Y^0.9811`` in xyY, chromaticity kept."""
    xyz = convert(rgb, "ap1_to_xyz")
    big_x, big_y, big_z = xyz.split(1, dim=-3)
    total = (big_x + big_y + big_z).clamp_min(1e-4)
    x, y = big_x / total, big_y / total
    new_y = big_y.clamp(0.0, 65504.0)
    new_y = torch.where(new_y > 0, torch.where(new_y > 0, new_y, torch.ones_like(new_y)) ** _DIM_SURROUND_GAMMA, new_y)
    m = new_y / y.clamp_min(1e-4)
    xyz = torch.cat((x * m, new_y, (1.0 - x - y) * m), dim=-3)
    return convert(xyz, "xyz_to_ap1")


def aces_fitted(aces: torch.Tensor) -> torch.Tensor:
    """Unity ``AcesTonemap`` on ACES2065-1 input: RRT glow and red modifier, desaturation, the luminance
    fit ``x (a x + b) / (x (c x + d) + e)`` of RRT+ODT (RGB monitor, 100 nits, dim), dim surround,
    ODT desaturation, then AP1 → XYZ → D60→D65 → Rec.709."""
    aces = _rrt_glow_and_red_modifier(aces, _smoothstep_hue_weight)
    acescg = _lerp_to_luminance(convert(aces, "ap0_to_ap1").clamp_min(0.0), _RRT_SAT_FACTOR)
    k = _ACES_FIT
    fitted = acescg * (k["a"] * acescg + k["b"]) / (acescg * (k["c"] * acescg + k["d"]) + k["e"])
    linear = _lerp_to_luminance(_dark_to_dim_surround(fitted), _ODT_SAT_FACTOR)
    return convert(convert(convert(linear, "ap1_to_xyz"), "d60_to_d65"), "xyz_to_rec709")


def aces(image: torch.Tensor) -> torch.Tensor:
    """ACES filmic tone mapping as Unity does it: ``AcesTonemap(unity_to_ACES(min(x, 60)))`` (HDR §3.5)."""
    return _display(aces_fitted(unity_to_aces(_limited(image))))


# --- ACES 1.0.3 reference rendering: RRT + ODT "RGB monitor 100 nits dim" (aces-dev CTL) ---

_HALF_MIN = 5.96046448e-08
"""Smallest positive half float: the CTL's floor before ``log10`` in the tone scales."""
_CINEMA_WHITE, _CINEMA_BLACK = 48.0, 0.02
"""Luminance (cd/m²) of the ODT's reference white and black, mapped to code values 1 and 0."""

_SPLINE_BASIS = torch.tensor(((0.5, -1.0, 0.5), (-1.0, 1.0, 0.5), (0.5, 0.0, 0.0)), dtype=torch.float64)
"""The CTL's quadratic B-spline basis ``M``: ``log y = (t², t, 1) · (cᵀ M)`` on each knot interval."""


class _SegmentedSpline:
    """ACES ``SegmentedSplineParams_c5``/``c9``: a tone scale in log10-log10 space.

    Between ``min_point`` and ``mid_point`` (and ``mid_point``/``max_point``) the curve is a uniform
    quadratic B-spline with ``knots - 1`` intervals through ``coefs_low`` (``coefs_high``); beyond
    them, straight lines of slope ``slope_low``/``slope_high``. Points are ``(x, y)`` in linear units.
    """

    def __init__(self, coefs_low, coefs_high, min_point, mid_point, max_point, slope_low, slope_high, knots):
        self.low = self._interval_polynomials(coefs_low, knots)
        self.high = self._interval_polynomials(coefs_high, knots)
        self.log_min, self.log_mid, self.log_max = (tuple(math.log10(v) for v in p) for p in (min_point, mid_point, max_point))
        self.slope_low, self.slope_high = slope_low, slope_high

    @staticmethod
    def _interval_polynomials(coefs, knots) -> torch.Tensor:
        """``(knots - 1, 3)``: the quadratic ``(a, b, c)`` of ``a t² + b t + c`` on each interval."""
        c = torch.tensor(coefs, dtype=torch.float64)
        return torch.stack([c[j : j + 3] @ _SPLINE_BASIS for j in range(knots - 1)])

    @staticmethod
    def _bspline(log_x: torch.Tensor, polynomials: torch.Tensor, start: float, end: float) -> torch.Tensor:
        """The spline between ``start`` and ``end`` (log10 x): interval ``j`` and ``t`` in [0, 1) from the knot coordinate."""
        intervals = polynomials.shape[0]
        knot = (log_x - start) * (intervals / (end - start))
        j = knot.detach().floor().clamp(0, intervals - 1)
        t = knot - j
        a, b, c = polynomials.to(log_x)[j.long()].unbind(-1)
        return (a * t + b) * t + c

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """``segmented_spline_c5_fwd``/``c9_fwd``: ``10^spline(log10(max(x, HALF_MIN)))``."""
        log_x = torch.log10(x.clamp_min(_HALF_MIN))
        below = self.slope_low * (log_x - self.log_min[0]) + self.log_min[1]
        above = self.slope_high * (log_x - self.log_max[0]) + self.log_max[1]
        low = self._bspline(log_x, self.low, self.log_min[0], self.log_mid[0])
        high = self._bspline(log_x, self.high, self.log_mid[0], self.log_max[0])
        log_y = torch.where(
            log_x <= self.log_min[0],
            below,
            torch.where(log_x < self.log_mid[0], low, torch.where(log_x < self.log_max[0], high, above)),
        )
        return torch.pow(10.0, log_y)


_RRT_TONESCALE = _SegmentedSpline(
    coefs_low=(-4.0, -4.0, -3.1573765773, -0.4852499958, 1.8477324706, 1.8477324706),
    coefs_high=(-0.7185482425, 2.0810307172, 3.6681241237, 4.0, 4.0, 4.0),
    min_point=(0.18 * 2.0**-15, 0.0001),
    mid_point=(0.18, 4.8),
    max_point=(0.18 * 2.0**18, 10000.0),
    slope_low=0.0,
    slope_high=0.0,
    knots=4,
)
"""``RRT_PARAMS`` of the RRT's ``segmented_spline_c5_fwd`` (scene-linear AP1 → OCES luminance)."""


def _rrt_tonescale_of(x: float) -> float:
    return _RRT_TONESCALE(torch.tensor(x, dtype=torch.float64)).item()


_ODT_TONESCALE_48_NITS = _SegmentedSpline(
    coefs_low=(-1.6989700043, -1.6989700043, -1.4779, -1.2291, -0.8648, -0.448, 0.00518, 0.4511080334, 0.9113744414, 0.9113744414),
    coefs_high=(0.5154386965, 0.8470437783, 1.1358, 1.3802, 1.5197, 1.5985, 1.6467, 1.6746091357, 1.687873339, 1.687873339),
    min_point=(_rrt_tonescale_of(0.18 * 2.0**-6.5), 0.02),
    mid_point=(_rrt_tonescale_of(0.18), 4.8),
    max_point=(_rrt_tonescale_of(0.18 * 2.0**6.5), 48.0),
    slope_low=0.0,
    slope_high=0.04,
    knots=8,
)
"""``ODT_48nits`` of the ODT's ``segmented_spline_c9_fwd`` (OCES → 0.02..48 cd/m²)."""


def _ap1_y(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``AP1_RGB2Y``: luminance of ACEScg, the middle row of the AP1 → XYZ matrix (full precision)."""
    return torch.einsum("j,...jhw->...hw", matrix("ap1_to_xyz", rgb)[1], rgb).unsqueeze(-3)


def _ap1_desaturate(rgb: torch.Tensor, factor: float) -> torch.Tensor:
    """ACES ``calc_sat_adjust_matrix(factor, AP1_RGB2Y)``: ``Y + factor (rgb - Y)``."""
    y = _ap1_y(rgb)
    return y + factor * (rgb - y)


def _dark_to_dim_surround_exact(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``darkSurround_to_dimSurround``: ``Y → Y^0.9811`` keeping xy, i.e. ``rgb · Y^(0.9811 - 1)``.

    ``Y`` is AP1 luminance floored at 1e-10, as OpenColorIO's ``ACES_DarkToDim10``; unlike
    :func:`_dark_to_dim_surround` (Unity's, with 1e-4 floors) it leaves near-black pixels where they are.
    """
    return rgb * _ap1_y(rgb).clamp_min(1e-10) ** (_DIM_SURROUND_GAMMA - 1.0)


def aces_reference(image: torch.Tensor) -> torch.Tensor:
    """The full ACES 1.0.3 rendering: RRT + ODT "RGB monitor, 100 nits, dim" (aces-dev ``rrt.ctl``,
    ``ODT.Academy.RGBmonitor_100nits_dim.ctl``), display-linear Rec.709 (sRGB primaries, D65).

    Linear Rec.709 → ACES2065-1; RRT glow and red modifier (the CTL's cubic B-spline hue weight);
    AP1, clamped to [0, 65504]; desaturation 0.96; the RRT tone scale (``segmented_spline_c5``) and
    the ODT tone scale (``segmented_spline_c9``, 48 nits) per channel (the RRT's AP1 → AP0 and the
    ODT's AP0 → AP1 cancel); ``Y_2_linCV`` (0.02..48 cd/m² → 0..1); dark → dim surround (γ 0.9811);
    desaturation 0.93; AP1 → XYZ → Bradford D60 → D65 → Rec.709; clip to [0, 1]. Encoding with
    :func:`torchgrade.color.linear_to_srgb` gives OpenColorIO's "ACES 1.0 - SDR Video" view of the
    "sRGB - Display".
    """
    aces = _rrt_glow_and_red_modifier(unity_to_aces(_limited(image)), _cubic_basis_hue_weight)
    acescg = _ap1_desaturate(convert(aces.clamp_min(0.0), "ap0_to_ap1").clamp(0.0, HALF_MAX), _RRT_SAT_FACTOR)
    luminance_cd = _ODT_TONESCALE_48_NITS(_RRT_TONESCALE(acescg))
    code_values = (luminance_cd - _CINEMA_BLACK) / (_CINEMA_WHITE - _CINEMA_BLACK)
    linear = _ap1_desaturate(_dark_to_dim_surround_exact(code_values), _ODT_SAT_FACTOR)
    return _display(convert(convert(convert(linear, "ap1_to_xyz"), "d60_to_d65"), "xyz_to_rec709"))


# --- Fits of ACES in games ---

_HILL_INPUT = ((0.59719, 0.35458, 0.04823), (0.07600, 0.90834, 0.01566), (0.02840, 0.13383, 0.83777))
_HILL_OUTPUT = ((1.60475, -0.53108, -0.07367), (-0.10208, 1.10813, -0.00605), (-0.00327, -0.07276, 1.07602))


def _apply_rows(rows, image: torch.Tensor) -> torch.Tensor:
    """Apply a constant 3x3 matrix, given as rows, to every pixel."""
    return apply_matrix(torch.tensor(rows, dtype=image.dtype, device=image.device), image)


def aces_hill(image: torch.Tensor) -> torch.Tensor:
    """Stephen Hill's ACES fit (BakingLab ``ACES.hlsl``, ``ACESFitted``): sRGB → RRT-saturation/AP1
    input matrix, ``RRTAndODTFit(v) = (v (v + 0.0245786) - 0.000090537) / (v (0.983729 v + 0.432951) + 0.238081)``,
    output matrix back to linear Rec.709 (ODT sRGB, 100 nits)."""
    v = _apply_rows(_HILL_INPUT, _limited(image))
    fitted = (v * (v + 0.0245786) - 0.000090537) / (v * (0.983729 * v + 0.4329510) + 0.238081)
    return _display(_apply_rows(_HILL_OUTPUT, fitted))


_NARKOWICZ_EXPOSURE = 0.6
"""Narkowicz's input scale: his curve was fitted to ACES with the input exposed by 0.6 (the blog's ``x *= 0.6``)."""


def aces_narkowicz(image: torch.Tensor) -> torch.Tensor:
    """Krzysztof Narkowicz's ACES luminance fit ("ACES Filmic Tone Mapping Curve", 2016), per channel:
    ``x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)`` with ``x = 0.6 · c``."""
    x = _limited(image) * _NARKOWICZ_EXPOSURE
    return _display(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14))


# --- AgX ---

_AGX_MIN_EV = math.log2(0.18) - 10.0
_AGX_MAX_EV = math.log2(0.18) + 6.5
"""AgX's log2 range: 10 stops below and 6.5 above middle grey 0.18 (−12.47393 .. 4.026069)."""
_AGX_INSET = (
    (0.842479062253094, 0.0784335999999992, 0.0792237451477643),
    (0.0423282422610123, 0.878468636469772, 0.0791661274605434),
    (0.0423756549057051, 0.0784336, 0.879142973793104),
)
_AGX_OUTSET = (
    (1.19687900512017, -0.0980208811401368, -0.0990297440797205),
    (-0.0528968517574562, 1.15190312990417, -0.0989611768448433),
    (-0.0529716355144438, -0.0980434501171241, 1.15107367264116),
)
_AGX_SIGMOID = (-0.00232, 0.1191, 0.4298, -6.868, 31.96, -40.14, 15.5)
"""Wrensch's 6th-order fit of AgX's default-contrast sigmoid, ascending powers (mean error² 3.67e-6)."""
_AGX_GODOT_INSET = (
    (0.54490813676363087053, 0.37377945959812267119, 0.081384976686647875101),
    (0.14044005884001287035, 0.75410959864013760045, 0.10543358536857773485),
    (0.088827411851915368603, 0.17887712465043811023, 0.73224999956948382528),
)
"""Godot 4.4: linear sRGB → Rec.2020, then Blender's AgX inset."""
_AGX_GODOT_OUTSET = (
    (1.9645509602733325934, -0.85585845117807513559, -0.10886710826831608324),
    (-0.29932243390911083839, 1.3264510741502356555, -0.027084020983874825605),
    (-0.16436833806080403409, -0.23822464068860595117, 1.402665347143271889),
)
"""Godot 4.4: Blender's AgX outset, then Rec.2020 → linear sRGB."""
_AGX_GODOT_SIGMOID = (0.0, 0.021, 4.0111, -25.682, 70.359, -74.778, 27.069)
"""Godot 4.4's 6th-order fit of Blender's AgX sigmoid (EaryChow's), ascending powers, zero at 0."""


def _polynomial(x: torch.Tensor, coefficients) -> torch.Tensor:
    """``Σ cₖ xᵏ`` by Horner's rule, ``coefficients`` in ascending powers."""
    result = torch.full_like(x, coefficients[-1])
    for c in reversed(coefficients[:-1]):
        result = result * x + c
    return result


def _agx_log_encoding(rgb: torch.Tensor) -> torch.Tensor:
    """``(clamp(log2 x, min_ev, max_ev) - min_ev) / (max_ev - min_ev)``: AgX's log2 shaper onto [0, 1]."""
    ev = torch.log2(rgb.clamp_min(1e-10)).clamp(_AGX_MIN_EV, _AGX_MAX_EV)
    return (ev - _AGX_MIN_EV) / (_AGX_MAX_EV - _AGX_MIN_EV)


def agx(image: torch.Tensor) -> torch.Tensor:
    """Troy Sobotka's AgX base in Benjamin Wrensch's "minimal AgX" form (iolite, 2023), display-linear.

    Inset matrix on linear Rec.709; log2 encoding over ``0.18 · 2^-10 .. 0.18 · 2^6.5``; the
    6th-order polynomial fit of the default-contrast sigmoid; outset matrix; then the display's
    power-2.2 decode (``agxEotf``), so the output is display-linear Rec.709 (negative values, which
    the power leaves undefined, are clamped to 0).
    """
    encoded = _agx_log_encoding(_apply_rows(_AGX_INSET, _limited(image)))
    return _display(safe_pow(_apply_rows(_AGX_OUTSET, _polynomial(encoded, _AGX_SIGMOID)), 2.2))


def agx_godot(image: torch.Tensor) -> torch.Tensor:
    """Godot 4.4's AgX (``tonemap_agx``, ``tonemap.glsl``), an approximation of Blender 4's AgX base.

    Works in Rec.2020 with Blender's rotated inset/outset (folded into one matrix with the primaries
    conversion each way), log2 encoding as :func:`agx`, Godot's own 6th-order sigmoid fit, a power-2.4
    decode *before* the outset, and a display clip; the hue path differs from :func:`agx`.
    """
    encoded = _agx_log_encoding(_apply_rows(_AGX_GODOT_INSET, _limited(image)))
    return _display(_apply_rows(_AGX_GODOT_OUTSET, safe_pow(_polynomial(encoded, _AGX_GODOT_SIGMOID), 2.4)))


# --- Khronos PBR Neutral ---

_KHRONOS_F90 = 0.04
_KHRONOS_START_COMPRESSION = 0.8 - _KHRONOS_F90
_KHRONOS_DESATURATION = 0.15


def khronos_pbr_neutral(image: torch.Tensor) -> torch.Tensor:
    """Khronos PBR Neutral (Khronos 3D Commerce reference GLSL, ``PBRNeutralToneMapping``).

    Offset ``x - 6.25 x²`` below ``x = min(rgb) = 0.08``, else F90 = 0.04, subtracted from every
    channel; then where ``peak = max(rgb) ≥ Ks = 0.76``: scale to ``newPeak = 1 - d² / (peak + d - Ks)``
    (``d = 1 - Ks``) and mix towards ``newPeak`` grey by ``g = 1 - 1 / (Kd (peak - newPeak) + 1)``,
    Kd = 0.15. Below ``Ks`` colours pass through after the offset.
    """
    c = _limited(image)
    low = c.amin(dim=-3, keepdim=True)
    c = c - torch.where(low < 0.08, low - 6.25 * low * low, torch.full_like(low, _KHRONOS_F90))
    peak = c.amax(dim=-3, keepdim=True)
    compressing = peak.clamp_min(_KHRONOS_START_COMPRESSION)
    d = 1.0 - _KHRONOS_START_COMPRESSION
    new_peak = 1.0 - d * d / (compressing + d - _KHRONOS_START_COMPRESSION)
    scaled = c * (new_peak / compressing)
    g = 1.0 - 1.0 / (_KHRONOS_DESATURATION * (compressing - new_peak) + 1.0)
    compressed = scaled + g * (new_peak - scaled)
    return _display(torch.where(peak < _KHRONOS_START_COMPRESSION, c, compressed))


# --- Unreal Engine's film curve ---


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
) -> torch.Tensor:
    """Unreal Engine 4.15+'s filmic tone mapper (``FilmToneMap``) with its five controls and defaults.

    Linear Rec.709 → ACES2065-1; RRT glow and red modifier (Unreal's smoothstep hue weight); ACEScg,
    clamped at 0; desaturation 0.96; :func:`_film_curve` per channel on ``log10``; desaturation 0.93;
    clamped at 0; back to linear Rec.709.
    """
    names = ("slope", "toe", "shoulder", "black_clip", "white_clip")
    k = [scalar_param(v, image, n) for v, n in zip((slope, toe, shoulder, black_clip, white_clip), names)]
    aces = _rrt_glow_and_red_modifier(unity_to_aces(_limited(image)), _smoothstep_hue_weight)
    acescg = _ap1_desaturate(convert(aces, "ap0_to_ap1").clamp_min(0.0), _RRT_SAT_FACTOR)
    log_c = torch.log10(acescg.clamp_min(torch.finfo(acescg.dtype).tiny))
    toned = _ap1_desaturate(_film_curve(log_c, *k), _ODT_SAT_FACTOR).clamp_min(0.0)
    return _display(convert(convert(convert(toned, "ap1_to_xyz"), "d60_to_d65"), "xyz_to_rec709"))


def no_tonemap(image: torch.Tensor) -> torch.Tensor:
    """No curve: the display simply clips to [0, 1]."""
    return _display(image)


_CURVES = {
    "none": (no_tonemap, ()),
    "reinhard": (reinhard, ()),
    "reinhard_extended": (reinhard_extended, ("white_point",)),
    "reinhard_luminance": (reinhard_luminance, ("white_point",)),
    "neutral": (neutral, ()),
    "aces": (aces, ()),
    "hable": (hable, ("exposure_bias", "white_point")),
    "filmic": (filmic, tuple(inspect.signature(filmic).parameters)[1:]),
    "unreal_filmic": (unreal_filmic, tuple(inspect.signature(unreal_filmic).parameters)[1:]),
    "aces_reference": (aces_reference, ()),
    "aces_hill": (aces_hill, ()),
    "aces_narkowicz": (aces_narkowicz, ()),
    "agx": (agx, ()),
    "agx_godot": (agx_godot, ()),
    "khronos_pbr_neutral": (khronos_pbr_neutral, ()),
}
TONEMAP_MODES = tuple(_CURVES)
"""Every ``ToneMap`` mode."""

PARAM_RANGES = {
    "white_point": (1e-3, 1e4),
    "exposure_bias": (1e-3, 1e3),
    "shoulder_strength": (0.0, 10.0),
    "linear_strength": (0.0, 10.0),
    "linear_angle": (0.0, 10.0),
    "toe_strength": (1e-3, 10.0),
    "toe_numerator": (0.0, 10.0),
    "toe_denominator": (1e-3, 10.0),
    "slope": (0.01, 1.0),
    "toe": (0.0, 0.99),
    "shoulder": (0.0, 0.99),
    "black_clip": (0.0, 1.0),
    "white_clip": (0.0, 1.0),
}
"""Valid ``[low, high]`` of every curve parameter, by name (a name means the same in every mode).

Defaults are the curve functions' own (e.g. :func:`filmic`'s signature). Unreal's toe and shoulder stop
at 0.99 (at 1, with a zero clip, its toe or shoulder scale is 0); Hable's toe strength and denominator
stay positive so ``t``'s denominator does.
"""


def tonemap(image: torch.Tensor, mode: str = "neutral", clip: bool = True, **params: Param) -> torch.Tensor:
    """Apply tone mapper ``mode`` (one of :data:`TONEMAP_MODES`) with its parameters.

    The input passes the library's non-finite policy first; float16/bfloat16 inputs are computed in
    float32 and returned in their own dtype. ``clip=False`` skips the final clip to [0, 1] (used
    when baking a LUT that clips after its lookup, :func:`torchgrade.lut.bake_lut`).
    """
    check_image(image)
    curve, names = _curve(mode)
    unknown = set(params) - set(names)
    if unknown:
        raise ValueError(f"tone mapper {mode!r} takes {list(names) or 'no parameters'}, got {sorted(unknown)}")
    working = sanitize(working_dtype(image))
    token = _CLIP.set(clip)
    try:
        return to_input_dtype(curve(working, **params), image)
    finally:
        _CLIP.reset(token)


def _curve(mode: str):
    if mode not in _CURVES:
        raise ValueError(f"unknown tone mapping mode {mode!r}; choose one of {', '.join(TONEMAP_MODES)}")
    return _CURVES[mode]


class ToneMap(ParamModule):
    """Tone mapping layer: ``ToneMap(mode="neutral", **curve_params)``; see :data:`TONEMAP_MODES`.

    Each mode takes the parameters named in its curve function, with that function's defaults
    (``white_point``: 4 for ``reinhard_extended`` and ``reinhard_luminance``, 11.2 for ``hable`` and
    ``filmic``; ``exposure_bias``: 2; Hable's six ``filmic`` parameters; Unreal's ``slope``, ``toe``,
    ``shoulder``, ``black_clip``, ``white_clip``), checked against :data:`PARAM_RANGES`. Each accepts a
    number, a 0-d or per-sample ``(B,)`` tensor, or an ``nn.Parameter`` to learn it.
    """

    def __init__(
        self, mode: str = "neutral", white_point: Param | None = None, exposure_bias: Param | None = None, clip: bool = True, **curve_params: Param
    ):
        super().__init__()
        curve, names = _curve(mode)
        self.mode = mode
        self.clip = bool(clip)
        given = {"white_point": white_point, "exposure_bias": exposure_bias, **curve_params}
        for name, value in given.items():
            if value is not None and name not in names:
                raise ValueError(f"tone mapper {mode!r} takes no {name!r}; it takes {list(names) or 'no parameters'}")
        defaults = inspect.signature(curve).parameters
        for name in names:
            value = defaults[name].default if given.get(name) is None else given[name]
            check_range(value, name, *PARAM_RANGES[name])
            self.set_param(name, value)

    @property
    def is_identity(self) -> bool:
        """Tone mapping is never skipped: even ``"none"`` clips to the display range."""
        return False

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return tonemap(image, self.mode, clip=self.clip, **self.params())

    def extra_repr(self) -> str:
        return f"mode={self.mode!r}" + "".join(f", {k}={v}" for k, v in self.config().items() if k != "mode")

    def config(self) -> dict:
        """The constructor arguments as plain values."""
        return {"mode": self.mode, **({} if self.clip else {"clip": False}), **self.plain_params()}
