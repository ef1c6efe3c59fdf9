"""ACES 2.0 gamut compression: pull (J, M) along a focus-directed line onto the limiting gamut's hull.

Source: Academy aces-core ``Lib.Academy.OutputTransform.ctl`` (``gamutMapper``) and OpenColorIO
``ops/fixedfunction/ACES2/Transform.cpp`` (``compressGamut``). The hull at a hue is approximated by
two power curves meeting at the cusp (lower gamma fixed per peak, upper gamma from the cusp table)
joined by a smooth minimum; colours beyond 0.75 of the hull (more when the hull is near the reach
boundary) are compressed with a Reinhard curve that maps the AP1 reach boundary onto the hull.

The helpers work on tensors of any shape and dtype, so the cusp-table builder and the per-pixel
path share them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ...color import safe_pow, safe_sqrt
from ...runtime import affine, constant, device_cached, values_of, where

__all__ = ["HueSearch", "GamutParams", "gamut_compress", "focus_gain", "solve_j_intersect", "compression_slope",
           "hull_boundary_m", "focus_j"]

SMOOTH_CUSPS = 0.12
SMOOTH_M = 0.27
CUSP_MID_BLEND = 1.3
FOCUS_GAIN_BLEND = 0.3
FOCUS_DISTANCE = 1.35
FOCUS_DISTANCE_SCALING = 1.75
COMPRESSION_THRESHOLD = 0.75


def _nonzero(x: torch.Tensor) -> torch.Tensor:
    return where(x == 0, 1.0, x)


def focus_j(cusp_j, mid_j: float, limit_j_max: float):
    """Focus point on the J axis: ``lerp(J_cusp, J_mid, min(1, 1.3 - J_cusp / J_max))``.

    Examples:
        >>> round(float(focus_j(torch.tensor(60.0), 34.1, 100.0)), 2)  # 0.7 of the way from 60 to 34.1
        41.87
    """
    w = (CUSP_MID_BLEND - cusp_j / limit_j_max).clamp(max=1.0)
    return cusp_j + (mid_j - cusp_j) * w


def focus_gain(j, threshold, limit_j_max: float, focus_dist: float):
    """Slope gain ``J_max d``, times ``1 + log10((J_max - thr) / max(1e-4, J_max - J))²`` above ``thr``.

    Examples:
        >>> [round(v, 2) for v in focus_gain(torch.tensor([10.0, 99.0]), torch.tensor(80.0), 100.0, 1.35).tolist()]
        [135.0, 363.51]
    """
    above = j > threshold
    ratio = (limit_j_max - threshold) / (limit_j_max - j).clamp_min(0.0001)
    adjust = torch.log10(where(above, ratio, 1.0))
    return limit_j_max * focus_dist * (adjust * adjust + 1.0)


def solve_j_intersect(j, m, focus, limit_j_max: float, gain):
    """J where the compression line through (J, M) meets the J axis: the stable root of its quadratic.

    Examples:
        >>> t = torch.tensor
        >>> float(solve_j_intersect(t(50.0), t(0.0), t(40.0), 100.0, t(135.0)))  # M = 0: J itself
        50.0
    """
    ms = m / gain
    a = ms / focus
    below = j < focus
    b_lo = 1.0 - ms
    lo = 2.0 * j / _nonzero(b_lo + safe_sqrt(torch.addcmul(b_lo * b_lo, a, j, value=4.0)))
    b_hi = affine(torch.add(ms, a, alpha=limit_j_max), -1.0, -1.0)  # -(1 + ms + J_max a)
    c_hi = torch.add(j, ms, alpha=limit_j_max)
    hi = -2.0 * c_hi / _nonzero(b_hi - safe_sqrt(torch.addcmul(b_hi * b_hi, a, c_hi, value=-4.0)))
    return torch.where(below, lo, hi)


def compression_slope(j_intersect, focus, limit_j_max: float, gain):
    """Slope dJ/dM of the line: ``s (J_i - J_focus) / (J_focus gain)``, ``s = J_i`` below focus else ``J_max - J_i``.

    Examples:
        >>> t = torch.tensor
        >>> round(float(compression_slope(t(50.0), t(40.0), 100.0, t(135.0))), 4)  # 50 * 10 / (40 * 135)
        0.0926
    """
    scale = torch.where(j_intersect < focus, j_intersect, limit_j_max - j_intersect)
    return scale * (j_intersect - focus) / (focus * gain)


def _line_hull_m(j_axis, slope, inv_gamma, j_max, m_max, j_ref):
    """Approximate M where ``J = slope M + J_axis`` meets ``J = J_max (M / M_max)^gamma`` (reference method)."""
    shifted = j_ref * safe_pow(j_axis / j_ref, inv_gamma)
    return shifted * m_max / _nonzero(j_max - slope * m_max)


def hull_boundary_m(cusp_j, cusp_m, limit_j_max: float, top_inv, bottom_inv, j_intersect, slope, j_cusp_intersect):
    """M of the limiting hull on the line: smooth minimum (cubic, width ``0.12 M_cusp``) of lower and upper curves.

    Examples:
        >>> t = torch.tensor
        >>> m = hull_boundary_m(t(60.0), t(70.0), 100.0, t(1.1), 0.88, t(60.0), t(0.0), t(60.0))
        >>> round(float(m), 2)  # through the cusp: M_cusp - 0.12 M_cusp / 6 (smooth minimum)
        68.6
    """
    lower = _line_hull_m(j_intersect, slope, bottom_inv, cusp_j, cusp_m, j_cusp_intersect)
    upper = _line_hull_m(limit_j_max - j_intersect, -slope, top_inv, limit_j_max - cusp_j, cusp_m,
                         limit_j_max - j_cusp_intersect)
    width = SMOOTH_CUSPS * cusp_m
    h = (width - (lower - upper).abs()).clamp_min(0.0) / width
    return torch.minimum(lower, upper) - h * h * h * width / 6.0


def _remap_m(m, gamut_m, reach_m):
    """Reinhard-style compression above ``threshold = max(gamut/reach, 0.75) gamut``, reach -> gamut."""
    proportion = (gamut_m / reach_m).clamp_min(COMPRESSION_THRESHOLD)
    threshold = proportion * gamut_m
    active = (m > threshold) & (proportion < 1.0)
    gamut_off = where(active, gamut_m - threshold, 1.0)
    reach_off = where(active, reach_m - threshold, 2.0)
    scale = reach_off / (reach_off / gamut_off - 1.0)
    nd = (m - threshold) / scale
    return torch.where(active, threshold + scale * nd / (1.0 + nd), m)


@dataclass(frozen=True, eq=False)
class HueSearch:
    """How many entries of an ascending table of hues lie below a hue, found by a look-up instead of a search: bin ``k``
    of the hues' span (``floor(h · scale)``) holds the count below it (``below``, as tuples of numbers) and the one entry
    that can lie in it (``entries``; ``inf`` where none does). The bins are narrower than two thirds of the closest two
    entries, and reach a quarter bin into their neighbours, so a hue rounded into the next bin still finds its count.
    A gather, a comparison and a sum: eager, three operations where a search is one; compiled, loads of the pixels'
    loop, where a search is a call of its own; exported, ``Gather`` nodes (ONNX has no search).

    Examples:
        >>> search = HueSearch.of(torch.tensor([0.0, 90.0, 180.0, 270.0, 360.0]))
        >>> search.count(torch.tensor([0.0, 45.0, 90.0, 90.5, 359.9, 360.0])).tolist()
        [0, 1, 1, 2, 4, 4]
    """

    scale: float
    below: tuple
    entries: tuple

    @classmethod
    def of(cls, hues: torch.Tensor, span: float = 360.0) -> "HueSearch":
        hues = hues.double()
        closest = float((hues[1:] - hues[:-1]).min())
        bins = 1 << math.ceil(math.log2(1.5 * span / closest))
        width = span / bins
        starts = torch.arange(bins, dtype=torch.float64) * width
        below = torch.searchsorted(hues, starts - width / 4)
        ahead = hues[below.clamp(max=len(hues) - 1)]
        entries = torch.where((below < len(hues)) & (ahead < starts + width * 1.25), ahead, math.inf)
        return cls(bins / span, tuple(below.tolist()), values_of(entries))

    def count(self, h: torch.Tensor) -> torch.Tensor:
        """The entries below each hue ``h`` (in ``[0, span)``): ``torch.searchsorted(hues, h)``."""
        below, entries = _search_tables(self, h.dtype, h.device)
        k = (h * self.scale).long().clamp(0, len(self.below) - 1)
        return below[k] + (entries[k] < h)


@device_cached
def _search_tables(search: HueSearch, dtype: torch.dtype, device: torch.device) -> tuple:
    """A :class:`HueSearch`'s counts (int64) and entries (``dtype``) on ``device``, made once (a search is hashed by
    identity, not by its thousands of numbers)."""
    return (torch.tensor(search.below, dtype=torch.long, device=device),
            torch.tensor(search.entries, dtype=dtype, device=device))


class GamutParams:
    """Per-peak constants and hue tables of the gamut compression (see :mod:`.tables`).

    Examples:
        >>> from torchgrade.tonemap.aces2.transform import Aces2Output
        >>> params = Aces2Output(100.0, "rec709").gamut
        >>> params.hues.ndim, params.cusps.shape[-1]
        (1, 3)
    """

    def __init__(self, limit_j_max, mid_j, focus_dist, lower_inv, model_gamma_inv, hues, cusps, reach):
        self.limit_j_max, self.mid_j, self.focus_dist = limit_j_max, mid_j, focus_dist
        self.lower_inv, self.model_gamma_inv = lower_inv, model_gamma_inv
        self.hues, self.cusps, self.reach = hues, cusps, reach
        # the tables as tuples of floats: device constants of a compiled graph, not inputs copied at every call; the
        # segment tables by column, so that a gather gives each column as a plane (:func:`_gathered_columns`)
        self.hue_values = values_of(hues)
        self.hue_search = HueSearch.of(hues)
        self.cusp_segments = _segment_columns(hues, cusps)
        self.reach_segments = values_of(torch.stack((reach, reach.roll(-1) - reach)))  # value, step to the next degree

    def cusp(self, h: torch.Tensor, planes: bool = False):
        """``(J_cusp, M_cusp, 1/gamma_top)`` at hue ``h``: linear in the non-uniform hue table (``planes``: the table's
        rows gathered one by one, :func:`_gathered_columns`).

        Examples:
            >>> from torchgrade.tonemap.aces2.transform import _output
            >>> p = _output(100.0, "rec709").gamut
            >>> # J, M, 1/gamma of the green-yellow cusp
            >>> [round(float(v), 1) for v in p.cusp(torch.tensor([120.0], dtype=torch.float64))]
            [86.8, 57.3, 1.1]
        """
        hi = self.hue_search.count(h.detach()).clamp(1, len(self.hue_values) - 1)
        segment = _gathered_columns(constant(self.cusp_segments, h), hi, planes)
        t = (h - segment[0]) * segment[1]
        if planes:
            return tuple(torch.addcmul(value, step, t) for value, step in zip(segment[2:5], segment[5:]))
        return torch.addcmul(segment[2:5], segment[5:], t).unbind(0)

    def reach_m(self, h: torch.Tensor, planes: bool = False) -> torch.Tensor:
        """AP1 reach M at ``J_max``, linear between whole degrees (``planes`` as :meth:`cusp`'s).

        Examples:
            >>> from torchgrade.tonemap.aces2.transform import _output
            >>> round(float(_output(100.0, "rec709").gamut.reach_m(torch.tensor(0.0, dtype=torch.float64))), 1)
            166.8
        """
        base = torch.floor(h.detach())
        segment = _gathered_columns(constant(self.reach_segments, h), base.long().remainder(360), planes)
        return torch.addcmul(segment[0], segment[1], h - base)


def _segment_columns(knots: torch.Tensor, values: torch.Tensor) -> tuple:
    """A piecewise-linear table as one column per interval, gathered at once: column ``k`` (from 1) holds interval
    ``k - 1``'s ``(knot, 1 / width, values, steps to the next values)``; column 0 repeats column 1. As tuples
    (:func:`values_of`).

    Examples:
        >>> _segment_columns(torch.tensor([0.0, 2.0]), torch.tensor([[1.0], [5.0]]))
        ((0.0, 0.0), (0.5, 0.5), (1.0, 1.0), (4.0, 4.0))
    """
    rows = torch.cat(((knots[:-1]).unsqueeze(-1), (1.0 / (knots[1:] - knots[:-1])).unsqueeze(-1), values[:-1],
                      values[1:] - values[:-1]), dim=-1)
    return values_of(torch.cat((rows[:1], rows)).T)


def _gathered_columns(table: torch.Tensor, index: torch.Tensor, planes: bool = False):
    """``(C, *index.shape)``: the columns ``index`` of a ``(C, K)`` table, each row of the table a plane; with
    ``planes``, each row gathered on its own, as a tuple of the ``C`` planes.

    By column, not ``table.T[index]``: CUDA gathers rows of a multiple of 16 bytes (the cusp table's 8 values) with a
    block of threads per pixel (about a third of ACES 2.0's 4K frame on an H200: ``benchmarks/results/gpu.md``, run D),
    and the planes it would give are strided. On planes (the form a compiler fuses), each row's gather is a load of
    the pixels' loop, where the ``(C, ...)`` gather is a loop of its own whose planes the frame's loop then reads back.

    Examples:
        >>> table, index = torch.tensor([[0.0, 10.0, 20.0], [1.0, 2.0, 3.0]]), torch.tensor([[2, 0]])
        >>> _gathered_columns(table, index).tolist(), [row.tolist() for row in _gathered_columns(table, index, planes=True)]
        ([[[20.0, 0.0]], [[3.0, 1.0]]], [[[20.0, 0.0]], [[3.0, 1.0]]])
    """
    if planes:
        return tuple(row[index] for row in table)
    return table.index_select(1, index.reshape(-1)).view(table.shape[0], *index.shape)


def gamut_compress(j, m, h, reach_m, p: GamutParams, planes: bool = False):
    """Compressed ``(J, M)``: ``J <= 0`` -> black, ``M <= 0`` or ``J > J_max`` -> ``(J, 0)``, else the hull mapping
    (``planes``: :meth:`GamutParams.cusp`'s).

    Examples:
        >>> from torchgrade.tonemap.aces2.transform import _output
        >>> p = _output(100.0, "rec709").gamut
        >>> j, m, h = (torch.tensor([v], dtype=torch.float64) for v in (50.0, 300.0, 120.0))
        >>> j_out, m_out = gamut_compress(j, m, h, p.reach_m(h), p)
        >>> bool(m_out < m)  # far outside Rec.709: pulled in
        True
    """
    cusp_j, cusp_m, top_inv = p.cusp(h, planes)
    focus = focus_j(cusp_j, p.mid_j, p.limit_j_max)
    threshold = cusp_j + (p.limit_j_max - cusp_j) * FOCUS_GAIN_BLEND
    gain = focus_gain(j, threshold, p.limit_j_max, p.focus_dist)
    j_i = solve_j_intersect(j, m, focus, p.limit_j_max, gain)
    slope = compression_slope(j_i, focus, p.limit_j_max, gain)
    j_ic = solve_j_intersect(cusp_j, cusp_m, focus, p.limit_j_max, gain)
    gamut_m = hull_boundary_m(cusp_j, cusp_m, p.limit_j_max, top_inv, p.lower_inv, j_i, slope, j_ic)
    reach_bound = _line_hull_m(j_i, slope, p.model_gamma_inv, p.limit_j_max, reach_m, p.limit_j_max)
    active = (j > 0) & (m > 0) & (j <= p.limit_j_max) & (gamut_m > 0)
    safe_gamut = where(active, gamut_m, 1.0)
    safe_reach = where(active, reach_bound, 2.0)
    m_out = _remap_m(where(active, m, 0.0), safe_gamut, safe_reach)
    j_out = torch.where(active, j_i + m_out * slope, j.clamp_min(0.0))
    return j_out, where(active, m_out, 0.0)
