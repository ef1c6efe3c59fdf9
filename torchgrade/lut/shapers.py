"""LUT shapers: the 1D curve a :class:`~torchgrade.LUT3D` applies per channel before its lattice.

A shaper decides where the lattice's points go. Each is an object that knows its encoding
(linear input -> shaper code values), its decoding (for baking: the linear value a lattice point
is fed), its default lattice domain, and its ``.cube`` form (the Resolve 1D section
:func:`torchgrade.io.write_cube` writes, or the Adobe ``DOMAIN_MIN/MAX`` form alone).
Its ONNX form is its encoding itself: every encoding is made of traceable operators (LogC's
``Log``/``Where``, a curve's ``Gather``), so the exporter traces it as it runs in PyTorch.

A new shaper is one :class:`Shaper` subclass here plus one line in :data:`SHAPERS`.

Examples:
    >>> import torch
    >>> round(float(SHAPERS["logc"].encode(torch.zeros(1))), 4) == round(LOGC_BLACK, 4)
    True
    >>> SHAPERS["linear"].default_domain
    (0.0, 1.0)
"""

from __future__ import annotations

from typing import Optional

import torch

from ..base.images import HALF_MAX
from ..color import linear_to_logc, logc_to_linear

__all__ = ["Shaper", "LinearShaper", "LogCShaper", "LogCHDRShaper", "LogCExtendedShaper", "CurveShaper", "FittedShaper", "SHAPERS",
           "LOGC_BLACK", "LOGC_TOP", "LOGC_HALF_MAX", "DEFAULT_DOMAINS", "DEFAULT_SIZES", "shaper_encode", "shaper_decode",
           "sample_curve", "lattice_unit"]

LOGC_BLACK = float(linear_to_logc(torch.tensor(0.0, dtype=torch.float64)))
"""LogC code value of linear 0 (≈ 0.064 with Unity's constants): the bottom of the LogC lattice."""

LOGC_TOP = float(logc_to_linear(torch.tensor(1.0, dtype=torch.float64)))
"""Linear value of LogC code 1 (≈ 58.86): the top of the ``"logc"`` lattice, where ``"logc_hdr"``'s tail starts."""

LOGC_HALF_MAX = float(linear_to_logc(torch.tensor(HALF_MAX, dtype=torch.float64)))
"""LogC code value of the sanitize bound 65504 (≈ 1.744)."""


class Shaper:
    """A per-channel 1D curve before the lattice: ``encode`` linear ``(3, P)`` points to code values.

    ``curve`` and ``curve_range`` are the data of a tabulated shaper (:class:`CurveShaper`);
    analytic shapers ignore them.

    Examples:
        >>> import torch
        >>> SHAPERS["linear"].encode(torch.ones(3, 2)).shape
        torch.Size([3, 2])
    """

    name = ""
    default_domain = (0.0, 1.0)
    """Lattice domain ``(min, max)`` in code values when a LUT is given none."""
    default_size = 33
    """Lattice size a bake takes when given none."""
    bakeable = True
    """Whether :func:`~torchgrade.bake_lut` can bake through it (it has :meth:`decode`)."""
    cube_domain_form = False
    """Whether a ``.cube`` file states it with the Adobe ``DOMAIN_MIN/MAX`` keywords alone (no 1D section)."""
    takes_curve = False
    """Whether it is defined by a per-channel table (``LUT3D(curve=..., curve_range=...)``)."""

    def encode(self, points: torch.Tensor, curve: Optional[torch.Tensor] = None, curve_range=(0.0, 1.0)) -> torch.Tensor:
        """Shaper code values of linear points."""
        raise NotImplementedError

    def decode(self, codes: torch.Tensor, curve: Optional[torch.Tensor] = None, curve_range=(0.0, 1.0)) -> torch.Tensor:
        """Linear values of code values (the inverse of :meth:`encode`); per-channel shapers take ``(3, P)`` codes."""
        raise NotImplementedError(f"the {self.name!r} shaper has no inverse")

    def linear_range(self, domain_min: torch.Tensor, domain_max: torch.Tensor, curve_range) -> tuple:
        """``(low, high)``: the linear input range the lattice covers, over all channels."""
        return float(self.decode(domain_min.double()).min()), float(self.decode(domain_max.double()).max())

    def cube_range(self, lut) -> tuple:
        """``(low, high)``: the linear range a ``.cube`` 1D section of ``lut`` samples (:meth:`linear_range`)."""
        return self.linear_range(lut.domain_min, lut.domain_max, lut.curve_range)

    def cube_section(self, lut, count: int) -> tuple:
        """The Resolve ``.cube`` 1D section of ``lut``: ``(low, high, (count, 3) lattice coordinates)``.

        Samples are evenly spaced over :meth:`cube_range`; each holds :func:`lattice_unit` of its
        value, the coordinate the 3D table is read at, so a reader applies the shaper itself.
        """
        low, high = self.cube_range(lut)
        linear = torch.linspace(low, high, count, dtype=torch.float64).expand(3, count)
        unit = lattice_unit(linear, self, lut.domain_min.double(), lut.domain_max.double(), lut.curve, lut.curve_range)
        return low, high, unit.t()


class LinearShaper(Shaper):
    """No shaping: the lattice spreads evenly over ``[0, 1]``; a ``.cube`` gets the Adobe ``DOMAIN`` form.

    Examples:
        >>> LinearShaper().cube_domain_form
        True
    """

    name = "linear"
    cube_domain_form = True

    def encode(self, points, curve=None, curve_range=(0.0, 1.0)):
        return points

    def decode(self, codes, curve=None, curve_range=(0.0, 1.0)):
        return codes


class LogCShaper(Shaper):
    """Unity's ARRI LogC curve (Catlike Coding, Color Grading §3.4): the lattice reaches linear ≈ 58.9.

    The domain starts at ``LogC(0)``, not 0 as in the document: a lattice plane then lies exactly on
    black, where every grade and tone mapper has its ``max(0, ·)`` kink, and no lattice points are
    spent on negative inputs.

    Examples:
        >>> import torch
        >>> round(float(LogCShaper().decode(torch.tensor(1.0))), 1)
        58.9
    """

    name = "logc"
    default_domain = (LOGC_BLACK, 1.0)

    def encode(self, points, curve=None, curve_range=(0.0, 1.0)):
        return linear_to_logc(points)

    def decode(self, codes, curve=None, curve_range=(0.0, 1.0)):
        return logc_to_linear(codes)


class LogCHDRShaper(Shaper):
    """LogC up to code 1 (linear 58.86), then LogC compressed piecewise linearly up to 65504: no highlight clamps.

    ``code = min(c, 1) + sum_i r_i clamp(c - c_i, 0, c_(i+1) - c_i)`` with ``c = LogC(x)`` and the knots
    ``c_i`` of :attr:`TAIL` (1, 1.3, 1.744: linear 58.86, ≈ 997, 65504). Above 58.86 LogC is ``log10(a x)``
    to within 2e-4 stops, so each tail segment spaces the lattice evenly in stops. On the default domain
    a 33³ lattice keeps 27 of its 32 intervals for black to 58.86 and gives 4 to the next 4.1 stops
    (where lamps and speculars lie) and 1 to the last 6 stops; every knot lies on a lattice plane at
    every size ``2^n + 1`` from 33 up, so each cell lies within one segment (``benchmarks/results/lut.md``
    measures this trade).

    Examples:
        >>> import torch
        >>> shaper = LogCHDRShaper()
        >>> [round(float(shaper.decode(torch.tensor(v, dtype=torch.float64))), 2) for v in (1.0, shaper.default_domain[1])]
        [58.86, 65504.0]
    """

    name = "logc_hdr"
    BODY = 27
    """Lattice intervals from black to LogC code 1 at the default size."""
    TAIL = ((1.0, 0), (1.3, 4), (LOGC_HALF_MAX, 5))
    """``(LogC code, lattice intervals above code 1)`` at each knot of the tail, at the default size."""

    def __init__(self):
        step = (1.0 - LOGC_BLACK) / self.BODY
        self.knots = tuple(logc for logc, _ in self.TAIL)
        """The knots ``c_i`` in LogC code values."""
        self.codes = tuple(1.0 + step * intervals for _, intervals in self.TAIL)
        """The shaper's code value at each knot."""
        self.default_domain = (LOGC_BLACK, self.codes[-1])

    def encode(self, points, curve=None, curve_range=(0.0, 1.0)):
        return self._piecewise(linear_to_logc(points), self.knots, self.codes)

    def decode(self, codes, curve=None, curve_range=(0.0, 1.0)):
        return logc_to_linear(self._piecewise(codes, self.codes, self.knots))

    @staticmethod
    def _piecewise(values: torch.Tensor, start: tuple, end: tuple) -> torch.Tensor:
        """The identity up to ``start_0 = end_0``, then the segments joining the points ``(start_i, end_i)``, the last one
        unbounded (so the shaper keeps its slope at 65504): ``min(v, start_0) + sum_i r_i clamp(v, start_i, start_(i+1))
        - sum_i r_i start_i`` with ``r_i = (end_(i+1) - end_i) / (start_(i+1) - start_i)``, two operations a segment."""
        total, offset = values.clamp(max=start[0]), 0.0
        last = len(start) - 2
        for i, (low, high, out_low, out_high) in enumerate(zip(start, start[1:], end, end[1:])):
            slope = (out_high - out_low) / (high - low)
            total = total.add(values.clamp(low, None if i == last else high), alpha=slope)
            offset += slope * low
        return total - offset

    def logc_table(self, low: float, spacing: float = 0.1) -> tuple:
        """``((low, high), (n, 3) codes)``: the shaper after LogC as a table over LogC codes ``low + k spacing``.

        The knots lie on the table's points when ``spacing`` divides ``1 - low`` and 0.3, so linear
        interpolation in it is exact: the form CLF's ``LUT1D`` carries it in (:mod:`torchgrade.io.clf`).

        Examples:
            >>> (low, high), table = LogCHDRShaper().logc_table(0.0)
            >>> (low, round(high, 6), table.shape)
            (0.0, 1.8, torch.Size([19, 3]))
        """
        count = round((self.knots[-1] - low) / spacing + 0.5) + 1
        logc = low + spacing * torch.arange(count, dtype=torch.float64)
        codes = self._piecewise(logc, self.knots, self.codes)
        return (low, float(logc[-1])), codes.unsqueeze(1).expand(count, 3)

    def cube_range(self, lut) -> tuple:
        """Black (or the lattice bottom) to 58.86: a ``.cube`` 1D section spaced evenly in linear values up to 65504 would
        give everything below linear 1 one segment, so the file holds the LogC part and clamps above it, as a ``"logc"``
        LUT's does (CLF holds the tail exactly)."""
        low, high = self.linear_range(lut.domain_min, lut.domain_max, lut.curve_range)
        return low, min(high, LOGC_TOP)


class LogCExtendedShaper(LogCHDRShaper):
    """The ``"logc"`` lattice's spacing from black to 58.86, extended past it to 65504: the default for HDR looks.

    Below LogC code 1 it is LogC itself, on 38 intervals at the default size; above, the tail of
    :class:`LogCHDRShaper` (each segment even in stops) on 12 more intervals, 6 up to LogC 1.3 (≈ 997) and 6 up to
    65504: 51³ by default, whose knots lie on lattice planes (as at every size ``50 k + 1``). Its planes up to 58.86
    are the ``"logc"`` lattice's at :attr:`cube_size`, plane for plane, which is how a ``.cube`` file holds it. Chosen
    on photographs (``benchmarks/results/lut_lattices.md`` compares it with ``"logc"`` and ``"logc_hdr"`` at 33³),
    and it holds very bright saturated colours through every tone mapper but two within 2 codes.

    Examples:
        >>> import torch
        >>> shaper = LogCExtendedShaper()
        >>> shaper.default_size, shaper.cube_size, round(float(shaper.decode(torch.tensor(shaper.default_domain[1], dtype=torch.float64))))
        (51, 39, 65504)
    """

    name = "logc_extended"
    BODY = 38
    TAIL = ((1.0, 0), (1.3, 6), (LOGC_HALF_MAX, 12))
    default_size = BODY + TAIL[-1][1] + 1
    cube_size = BODY + 1
    """The ``"logc"`` lattice size whose planes are this lattice's up to 58.86 (its ``.cube`` form)."""


class CurveShaper(Shaper):
    """A per-channel 1D table over a linear input range, as ``.cube`` files carry it (read, never baked).

    Examples:
        >>> import torch
        >>> ramp = torch.linspace(0.0, 1.0, 5).unsqueeze(1).expand(5, 3)
        >>> CurveShaper().encode(torch.full((3, 1), 0.5), ramp, (0.0, 2.0)).flatten().tolist()
        [0.25, 0.25, 0.25]
    """

    name = "curve"
    bakeable = False
    takes_curve = True

    def encode(self, points, curve=None, curve_range=(0.0, 1.0)):
        return sample_curve(points, curve, curve_range)

    def linear_range(self, domain_min, domain_max, curve_range):
        return tuple(curve_range)


class FittedShaper(Shaper):
    """LogC, then a per-channel monotone curve fitted to a transform or a scene (:func:`~torchgrade.lut.fit_shaper`,
    :func:`~torchgrade.lut.fit_scene_shaper`).

    ``curve`` ``(n, 3)`` holds the lattice coordinate in [0, 1] at ``n`` LogC code values evenly
    over ``curve_range``; the lattice domain is [0, 1]. The fit puts lattice planes where the
    transform bends or where a scene's pixels are missed, from black to the half-float top (65504), so
    no HDR highlight is clamped.

    Examples:
        >>> import torch
        >>> ramp = torch.linspace(0.0, 1.0, 3).unsqueeze(1).expand(3, 3)
        >>> codes = FittedShaper().encode(torch.full((3, 1), 0.18), ramp, (0.0, 1.0))
        >>> torch.allclose(FittedShaper().decode(codes, ramp, (0.0, 1.0)), torch.full((3, 1), 0.18))
        True
    """

    name = "fitted"
    takes_curve = True

    def encode(self, points, curve=None, curve_range=(0.0, 1.0)):
        return sample_curve(linear_to_logc(points), curve, curve_range)

    def decode(self, codes, curve=None, curve_range=(0.0, 1.0)):
        low, high = curve_range
        steps = (curve.shape[0] - 1) / (high - low)
        logc = [low + _inverse_ramp(row, column.to(codes).contiguous()) / steps for row, column in zip(codes, curve.t())]
        return logc_to_linear(torch.stack(logc))

    def linear_range(self, domain_min, domain_max, curve_range):
        return tuple(float(logc_to_linear(torch.tensor(v, dtype=torch.float64))) for v in curve_range)


def _inverse_ramp(values: torch.Tensor, ramp: torch.Tensor) -> torch.Tensor:
    """Fractional index at which the strictly increasing ``ramp`` reaches each of ``values`` (clamped to its ends)."""
    values = values.clamp(float(ramp[0]), float(ramp[-1])).contiguous()
    upper = torch.searchsorted(ramp, values, right=True).clamp(1, ramp.numel() - 1)
    below, above = ramp[upper - 1], ramp[upper]
    return upper - 1 + (values - below) / (above - below)


SHAPERS: dict[str, Shaper] = {shaper.name: shaper for shaper in (LinearShaper(), LogCShaper(), LogCHDRShaper(), LogCExtendedShaper(), CurveShaper(),
                                               FittedShaper())}
"""The shapers by name, what ``LUT3D(shaper=...)`` takes."""

DEFAULT_DOMAINS = {name: shaper.default_domain for name, shaper in SHAPERS.items() if shaper.bakeable}
"""Lattice domain of each bakeable shaper, in shaper code values (LogC 1.0 is linear ≈ 58.86)."""

DEFAULT_SIZES = {name: shaper.default_size for name, shaper in SHAPERS.items() if shaper.bakeable}
"""Lattice size of each bakeable shaper's bakes when given none."""


def _shaper(shaper) -> Shaper:
    return SHAPERS[shaper] if isinstance(shaper, str) else shaper


def shaper_encode(points: torch.Tensor, shaper, curve: Optional[torch.Tensor] = None, curve_range=(0.0, 1.0)) -> torch.Tensor:
    """Shaper code values of linear ``(3, P)`` points; ``shaper`` is a name or a :class:`Shaper`.

    Examples:
        >>> import torch
        >>> shaper_encode(torch.ones(3, 1), "linear").flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    return _shaper(shaper).encode(points, curve, curve_range)


def shaper_decode(codes: torch.Tensor, shaper, curve: Optional[torch.Tensor] = None, curve_range=(0.0, 1.0)) -> torch.Tensor:
    """Linear values of shaper code values: the inverse of :func:`shaper_encode`.

    Examples:
        >>> import torch
        >>> round(float(shaper_decode(torch.tensor(LOGC_BLACK), "logc")), 6)
        0.0
    """
    return _shaper(shaper).decode(codes, curve, curve_range)


def sample_curve(points: torch.Tensor, curve: torch.Tensor, curve_range) -> torch.Tensor:
    """Per-channel 1D table lookup on ``(3, P)`` points, linear interpolation, inputs clamped to ``curve_range``.

    ``curve`` is ``(n, 3)``; entry ``k`` is the output at ``lo + k (hi - lo) / (n - 1)`` (a ``.cube`` 1D
    shaper, as Resolve and OpenColorIO read it).

    Examples:
        >>> import torch
        >>> curve = torch.tensor([[0.0] * 3, [1.0] * 3])
        >>> sample_curve(torch.full((3, 1), 0.25), curve, (0.0, 1.0)).flatten().tolist()
        [0.25, 0.25, 0.25]
    """
    lo, hi = curve_range
    n = curve.shape[0]
    position = ((points - lo) / (hi - lo)).clamp(0.0, 1.0) * (n - 1)
    index = position.floor().clamp(max=n - 2)
    fraction = position - index
    planar = curve.to(points).t()
    lower = torch.gather(planar, 1, index.long())
    upper = torch.gather(planar, 1, index.long() + 1)
    return lower + fraction * (upper - lower)


def lattice_unit(points, shaper, domain_min, domain_max, curve=None, curve_range=(0.0, 1.0)) -> torch.Tensor:
    """Normalised lattice coordinates ``u = clamp((shaper(x) - min) / (max - min), 0, 1)`` of ``(3, P)`` points.

    Examples:
        >>> import torch
        >>> lattice_unit(torch.tensor([[2.0], [0.5], [-1.0]]), "linear", 0.0, 1.0).flatten().tolist()
        [1.0, 0.5, 0.0]
    """
    low = _channel_column(domain_min, points)
    high = _channel_column(domain_max, points)
    codes = shaper_encode(points, shaper, curve, curve_range)
    return ((codes - low) / (high - low)).clamp(0.0, 1.0)


def _channel_column(value, like: torch.Tensor) -> torch.Tensor:
    """A number or RGB triple as a ``(3, 1)`` column in ``like``'s dtype and device."""
    return torch.as_tensor(value, dtype=like.dtype, device=like.device).reshape(-1, 1).expand(3, 1)
