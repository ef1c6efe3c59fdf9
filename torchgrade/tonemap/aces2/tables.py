"""Hue tables of the ACES 2.0 gamut compression, built once per (peak, limiting primaries) in float64.

Source: OpenColorIO ``ops/fixedfunction/ACES2/Transform.cpp`` (``make_reach_m_table``,
``make_uniform_hue_gamut_table``, ``make_upper_hull_gamma``), itself following aces-core
``Lib.Academy.OutputTransform.ctl``. Every search the reference runs hue by hue (bisection on M, on
position along a cube edge, on gamma) runs here for all 360 hues at once.
"""

from __future__ import annotations

import math

import torch

from .cam import REFERENCE_LUMINANCE, JMhParams, aab_to_jmh, jmh_to_rgb, rgb_to_aab
from .gamut import (FOCUS_GAIN_BLEND, SMOOTH_CUSPS, SMOOTH_M, compression_slope, focus_gain, focus_j,
                    hull_boundary_m, solve_j_intersect)

__all__ = ["reach_m_table", "hue_table", "hue_and_cusp_tables", "upper_hull_gamma"]

_F64 = torch.float64
_TEST_POSITIONS = (0.01, 0.1, 0.5, 0.8, 0.99)


def _jmh(rgb: torch.Tensor, p: JMhParams) -> torch.Tensor:
    j, m, h, _, _ = aab_to_jmh(rgb_to_aab(rgb, p, dim=-1), p, dim=-1)
    return torch.stack((j, m, h), -1)


def _to_rgb(j, m, h, p: JMhParams) -> torch.Tensor:
    rad = torch.deg2rad(h)
    return jmh_to_rgb(j, m, torch.cos(rad), torch.sin(rad), p, dim=-1)


def _bisect(lo, hi, inside, tolerance: float):
    """Shrink ``[lo, hi]`` around the boundary of ``inside`` (True below it) until narrower than ``tolerance``."""
    while bool(((hi - lo) > tolerance).any()):
        mid = (lo + hi) / 2
        ok = inside(mid)
        lo, hi = torch.where(ok, mid, lo), torch.where(ok, hi, mid)
    return lo, hi


def _step_then_bisect(inside, step: float, stop: float, tolerance: float, rows: int):
    """First multiple of ``step`` below ``stop`` where ``inside`` fails, then bisection (reference search)."""
    grid = torch.arange(step, stop - 1e-9, step, dtype=_F64)
    ok = torch.stack([inside(torch.full((rows,), g, dtype=_F64)) for g in grid.tolist()], -1)
    first_out = torch.where(ok.all(-1), grid.numel(), (~ok).to(torch.int64).argmax(-1))
    hi = (first_out + 1).to(_F64) * step
    return _bisect(hi - step, hi, inside, tolerance)[1]


def reach_m_table(reach: JMhParams, limit_j_max: float) -> torch.Tensor:
    """(360,) M at ``J_max`` where each whole-degree hue leaves the reach (AP1) gamut, to 0.01.

    Examples:
        >>> from torchgrade.color import AP1_CHROMATICITIES
        >>> from torchgrade.tonemap.aces2.cam import jmh_params
        >>> table = reach_m_table(jmh_params(AP1_CHROMATICITIES), 100.0)
        >>> table.shape, bool((table > 0).all())
        (torch.Size([360]), True)
    """
    hues = torch.arange(360, dtype=_F64)
    j = torch.full_like(hues, limit_j_max)
    return _step_then_bisect(lambda m: (_to_rgb(j, m, hues, reach) >= 0).all(-1), 50.0, 1300.0, 1e-2, 360)


def _corners() -> torch.Tensor:
    """Unit cube corners R, Y, G, C, B, M: the order in which their hues increase."""
    return torch.tensor(((1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1), (1, 0, 1)), dtype=_F64)


def _cycle(values: torch.Tensor, hue_col: torch.Tensor):
    """Rotate so the smallest hue is first, then pad one wrapped entry each side (8 rows)."""
    start = int(torch.argmin(hue_col))
    v = torch.roll(values, -start, 0)
    return torch.cat((v[-1:], v, v[:1]))


def _wrap_ends(jmh: torch.Tensor) -> torch.Tensor:
    jmh = jmh.clone()
    jmh[0, 2] -= 360.0
    jmh[-1, 2] += 360.0
    return jmh


def _reach_corners(reach: JMhParams, limit_j_max: float, forward_limit: float) -> torch.Tensor:
    """JMh of the reach cube's corners scaled (to 0.001) until their J reaches ``J_max``, in a hue cycle."""
    limit_a = (limit_j_max / 100.0) ** (1.0 / reach.cz)
    corners = _corners()

    def inside(scale):
        return rgb_to_aab(scale[:, None] * corners, reach, dim=-1)[:, 0] < limit_a

    _, hi = _bisect(torch.zeros(6, dtype=_F64), torch.full((6,), forward_limit, dtype=_F64), inside, 1e-3)
    jmh = _jmh(hi[:, None] * corners, reach)
    return _wrap_ends(_cycle(jmh, jmh[:, 2]))


def _display_corners(limit: JMhParams, peak: float):
    """RGB and JMh of the limiting cube's corners at peak white, in a hue cycle."""
    rgb = _corners() * (peak / REFERENCE_LUMINANCE)
    jmh = _jmh(rgb, limit)
    return _cycle(rgb, jmh[:, 2]), _wrap_ends(_cycle(jmh, jmh[:, 2]))


def _merged_hues(a: list, b: list) -> list:
    """Sorted union of two sorted hue lists, equal hues kept once."""
    return sorted(set(a) | set(b))


def _sample_counts(hues: list) -> list:
    """Table index for each corner hue: its rounded degree, nudged so no two corners share one."""
    counts: list[int] = []
    last, floor = None, 0 if hues[0] == 0.0 else 1
    for k, hue in enumerate(hues):
        idx = min(max(math.floor(hue + 0.5), floor), 359)
        if idx == last:
            if k > 1 and counts[k - 2] != counts[k - 1] - 1:
                counts[k - 1] -= 1
            else:
                idx += 1
        counts.append(min(idx, 359))
        last = floor = idx
    return counts


def hue_table(corner_hues: list) -> torch.Tensor:
    """(363,) hues: 360 samples, as uniform as possible, through every corner hue, plus wrap entries.

    Examples:
        >>> hues = hue_table([30.5, 100.2, 200.0])
        >>> hues.shape, [round(v, 1) for v in hues[32:34].tolist()]  # 30.5 sampled exactly
        (torch.Size([363]), [30.5, 31.5])
    """
    counts = _sample_counts(corner_hues)
    bounds = [0.0] + corner_hues + [360.0]
    sizes = [counts[0]] + [b - a for a, b in zip(counts, counts[1:])] + [360 - counts[-1]]
    parts = [lo + torch.arange(n, dtype=_F64) * ((hi - lo) / n) for lo, hi, n in zip(bounds, bounds[1:], sizes) if n]
    nominal = torch.cat(parts)
    return torch.cat((nominal[-1:] - 360.0, nominal, nominal[:2] + 360.0))


def _cusp_at(hues: torch.Tensor, rgb_corners: torch.Tensor, jmh_corners: torch.Tensor, limit: JMhParams):
    """(J, M) of the limiting cube's cusp at each hue: bisection along the cube edge between the two
    corners whose hues bracket it (the cusps of an RGB cube lie on its six R-Y-G-C-B-M edges)."""
    corner_hues = jmh_corners[:, 2]
    upper = torch.searchsorted(corner_hues[1:].contiguous(), hues, right=True).clamp(max=6) + 1
    lo_rgb, hi_rgb = rgb_corners[upper - 1], rgb_corners[upper]
    lo_hue, hi_hue = corner_hues[upper - 1], corner_hues[upper]

    def inside(t):
        h = _jmh(lo_rgb + (hi_rgb - lo_rgb) * t[:, None], limit)[:, 2]
        return (h >= lo_hue) & ((h >= hi_hue) | (h <= hues))

    lo, hi = _bisect(torch.zeros_like(hues), torch.ones_like(hues), inside, 1e-7)
    jmh = _jmh(lo_rgb + (hi_rgb - lo_rgb) * ((lo + hi) / 2)[:, None], limit)
    return jmh[:, 0], jmh[:, 1]


def hue_and_cusp_tables(reach: JMhParams, limit: JMhParams, peak: float, limit_j_max: float, forward_limit: float):
    """(363,) hue table and (363, 2) ``(J_cusp, M_cusp)`` of the limiting gamut, M widened by ``1 + 0.27 * 0.12``
    so the smoothed hull still encloses the true cusp.

    Examples:
        >>> from torchgrade.tonemap.aces2.transform import _output
        >>> p = _output(100.0, "rec709").gamut
        >>> p.hues.shape, p.cusps.shape  # J, M, 1/gamma_top per hue
        (torch.Size([363]), torch.Size([363, 3]))
    """
    reach_jmh = _reach_corners(reach, limit_j_max, forward_limit)
    rgb_corners, jmh_corners = _display_corners(limit, peak)
    hues = hue_table(_merged_hues(reach_jmh[1:7, 2].tolist(), jmh_corners[1:7, 2].tolist()))
    j, m = _cusp_at(hues[1:361], rgb_corners, jmh_corners, limit)
    cusps = torch.stack((j, m * (1.0 + SMOOTH_M * SMOOTH_CUSPS)), -1)
    return hues, torch.cat((cusps[-1:], cusps, cusps[:2]))


def upper_hull_gamma(hues, cusps, limit: JMhParams, peak: float, limit_j_max: float, mid_j: float,
                     focus_dist: float, lower_inv: float) -> torch.Tensor:
    """(363,) ``1/gamma`` of the upper hull per hue: the smallest gamma (to 1e-5, in steps of 0.4 then
    bisection) whose approximate hull puts all five test points on the upper edge outside the cube.

    Examples:
        >>> from torchgrade.tonemap.aces2.transform import _output
        >>> top = _output(100.0, "rec709").gamut.cusps[:, 2]
        >>> bool(((top > 1 / 5.2) & (top < 2.5)).all())  # 1/gamma with gamma in (0.4, 5.2]
        True
    """
    h, cusp_j, cusp_m = hues[1:361], cusps[1:361, 0], cusps[1:361, 1]
    focus = focus_j(cusp_j, mid_j, limit_j_max)
    threshold = cusp_j + (limit_j_max - cusp_j) * FOCUS_GAIN_BLEND
    tests = []
    for position in _TEST_POSITIONS:
        j = cusp_j + (limit_j_max - cusp_j) * position
        gain = focus_gain(j, threshold, limit_j_max, focus_dist)
        j_i = solve_j_intersect(j, cusp_m, focus, limit_j_max, gain)
        slope = compression_slope(j_i, focus, limit_j_max, gain)
        tests.append((j_i, slope, solve_j_intersect(cusp_j, cusp_m, focus, limit_j_max, gain)))

    def inside(gamma):
        fits = torch.ones_like(gamma, dtype=torch.bool)
        for j_i, slope, j_ic in tests:
            m = hull_boundary_m(cusp_j, cusp_m, limit_j_max, 1.0 / gamma, lower_inv, j_i, slope, j_ic)
            rgb = _to_rgb(j_i + slope * m, m, h, limit)
            fits &= (rgb > peak / REFERENCE_LUMINANCE).any(-1)
        return ~fits

    gamma = _step_then_bisect(inside, 0.4, 5.0, 1e-5, 360)
    top = 1.0 / gamma
    return torch.cat((top[-1:], top, top[:2]))
