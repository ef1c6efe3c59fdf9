"""The ACES 1.0.3 reference rendering: RRT + ODT "RGB monitor 100 nits dim", as the aces-dev CTL computes it."""

from __future__ import annotations

import math

import torch

from ...base.images import HALF_MAX
from ...color import convert
from ...runtime import constant, values_of
from .rrt import (
    ACES_TINY,
    ODT_SAT_FACTOR,
    RRT_SAT_FACTOR,
    ap1_desaturate,
    ap1_dim_surround,
    ap1_to_rec709,
    cubic_basis_hue_weight,
    rec709_to_aces,
    rrt_glow_and_red_modifier,
)
from ..base import display

__all__ = ["aces_reference"]

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
        # tuples of floats: device constants (runtime.constant), not tensors copied to the device at every call
        self.low = values_of(self._interval_polynomials(coefs_low, knots))
        self.high = values_of(self._interval_polynomials(coefs_high, knots))
        self.log_min, self.log_mid, self.log_max = (tuple(math.log10(v) for v in p) for p in (min_point, mid_point, max_point))
        self.slope_low, self.slope_high = slope_low, slope_high

    @staticmethod
    def _interval_polynomials(coefs, knots) -> torch.Tensor:
        """``(knots - 1, 3)``: the quadratic ``(a, b, c)`` of ``a t² + b t + c`` on each interval."""
        c = torch.tensor(coefs, dtype=torch.float64)
        return torch.stack([c[j : j + 3] @ _SPLINE_BASIS for j in range(knots - 1)])

    @staticmethod
    def _bspline(log_x: torch.Tensor, polynomials: tuple, start: float, end: float) -> torch.Tensor:
        """The spline between ``start`` and ``end`` (log10 x): interval ``j`` and ``t`` in [0, 1) from the knot coordinate."""
        intervals = len(polynomials)
        knot = (log_x - start) * (intervals / (end - start))
        j = knot.detach().floor().clamp(0, intervals - 1)
        t = knot - j
        a, b, c = constant(polynomials, log_x)[j.long()].unbind(-1)
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


def aces_reference(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """The full ACES 1.0.3 rendering: RRT + ODT "RGB monitor, 100 nits, dim" (aces-dev ``rrt.ctl``,
    ``ODT.Academy.RGBmonitor_100nits_dim.ctl``), display-linear Rec.709 (sRGB primaries, D65).

    Linear Rec.709 → ACES2065-1 (Bradford-adapted), unclamped: negative (out-of-gamut) and very bright values go through
    the RRT glow and red modifier (the CTL's cubic B-spline hue weight, its ``TINY`` = 1e-10) as the
    CTL's do; then, as ``rrt.ctl``, ACES clamped at 0 and AP1 clamped to [0, 65504]; desaturation
    0.96; the RRT tone scale (``segmented_spline_c5``) and the ODT tone scale (``segmented_spline_c9``, 48 nits) per channel (the RRT's AP1 → AP0 and the
    ODT's AP0 → AP1 cancel); ``Y_2_linCV`` (0.02..48 cd/m² → 0..1); dark → dim surround (γ 0.9811);
    desaturation 0.93; AP1 → XYZ → Bradford D60 → D65 → Rec.709; clip to [0, 1]. Encoding with
    :func:`torchgrade.color.linear_to_srgb` gives OpenColorIO's "ACES 1.0 - SDR Video" view of the
    "sRGB - Display" within 0.25 8-bit codes on every sample-image pixel; the rest is OpenColorIO
    recomputing the red modifier's saturation after the glow, where the CTL (and this) compute it
    once before.

    Examples:
        >>> [round(v, 3) for v in aces_reference(torch.tensor([0.18, 1.0, 5.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.104, 0.624, 0.926]
    """
    aces = rrt_glow_and_red_modifier(rec709_to_aces(image), cubic_basis_hue_weight, ACES_TINY)
    acescg = ap1_desaturate(convert(aces.clamp_min(0.0), "ap0_to_ap1").clamp(0.0, HALF_MAX), RRT_SAT_FACTOR)
    luminance_cd = _ODT_TONESCALE_48_NITS(_RRT_TONESCALE(acescg))
    code_values = (luminance_cd - _CINEMA_BLACK) / (_CINEMA_WHITE - _CINEMA_BLACK)
    linear = ap1_desaturate(ap1_dim_surround(code_values), ODT_SAT_FACTOR)
    return display(ap1_to_rec709(linear), clip)
