"""Fitting a LUT's per-channel shaper: lattice planes where the picture bends, or where a scene's pixels are missed.

**To the look** (:func:`fit_shaper`, no scene). Linear interpolation between lattice points spaced ``h`` apart
misses a curve by about ``h² |f''| / 8``, so the max error is smallest when ``h`` shrinks as ``1 / sqrt|f''|``:
the lattice density along each channel follows ``sqrt|f''|`` (error equidistribution). :func:`fit_shaper`
measures ``f''`` in what a viewer sees (8-bit sRGB display codes) along each input channel in LogC code space,
from black to the half-float top, sweeping that channel of a set of validation colours, and takes the largest
bend over output channels, averaged over base colours. A floor keeps a share of the lattice everywhere, so
colours the fit did not see are still covered. A 3D table's error also comes from bends across channels
(saturation, a ``max(0, ·)`` on an oblique surface), which one-channel sweeps do not see: :func:`refine_shaper`
then bakes the table, measures it, and moves lattice planes toward the LogC bands where the error is largest.

**To a scene** (:func:`fit_scene_shaper`). A scene's largest error sits in the cells its pixels fill, and on a
strong look it comes from bends across channels as much as along them, so the planes go where the scene is
missed, not where one channel bends. The start (:func:`start_planes`) spaces each channel's planes evenly in
``log2(x + c)`` (``c`` = :data:`SCENE_OFFSET`) from black to a top ``T`` on ``S - 3`` of the ``S - 1``
intervals; the next reaches on to the scene's largest value (at least one interval wide), and the last on to
the half-float top (65504; 1 for SDR), so nothing is clamped. ``T`` is :data:`SCENE_TOP_SCALE` times the
channel's :data:`SCENE_TOP_QUANTILE` quantile over the scene, at most its largest value: the scene's rarer,
brighter pixels (a lamp, the sun) share one interval, and none but those above the second-last plane's cap (one
even interval below the top: linear ~41,000 at 33³) shares the interval to 65504. A lattice fitted to a scene
needs at least 4 points a side.

Each of :data:`SCENE_ROUNDS` rounds bakes, fits the entries to the scene (:func:`~torchgrade.lut.fit_entries`,
scene pixels weighing :data:`SCENE_FIT_WEIGHT`) and measures every pixel's error; the next lattice resizes the
best one's intervals below the last by de Boor's equidistribution (:func:`move_planes`), by half as large a step
after a round that did not improve on the best. The lattice whose fitted table misses least wins. A fitted
table's errors are nearly level (it minimises their max), so a full step can overshoot; the halving keeps the
search from wandering.

The result is the curve of a :class:`~torchgrade.lut.FittedShaper`.

Examples:
    >>> import torch
    >>> curve, curve_range = fit_shaper(lambda image: image / (1 + image), knots=32)
    >>> curve.shape, float(curve[0, 0]), float(curve[-1, 0])
    (torch.Size([32, 3]), 0.0, 1.0)
"""

from __future__ import annotations

from typing import Callable

import torch
from tqdm import tqdm

from ..base.images import HALF_MAX
from ..color import linear_to_logc, linear_to_srgb, logc_to_linear
from .validation import validation_colours

__all__ = ["fit_shaper", "refine_shaper", "FIT_KNOTS", "FIT_BASES", "FIT_FLOOR", "FIT_ROUNDS", "FIT_BANDS",
           "fit_scene_shaper", "start_planes", "move_planes", "planes_curve", "SCENE_KNOTS", "SCENE_OFFSET",
           "SCENE_TOP_QUANTILE", "SCENE_TOP_SCALE", "SCENE_GAIN", "SCENE_FIT_WEIGHT", "SCENE_ROUNDS", "SCENE_MIN_SIZE"]

FIT_KNOTS = 512
"""Points of a fitted shaper's curve (LogC-spaced from black to 65504)."""

FIT_BASES = 96
"""Validation colours swept per channel."""

FIT_FLOOR = 0.15
"""Share of the lattice spread evenly in LogC whatever the transform does (for colours the fit did not see)."""

FIT_ROUNDS = 4
"""Bake-and-measure rounds of :func:`refine_shaper`."""

FIT_BANDS = 64
"""LogC bands per channel over which :func:`refine_shaper` attributes the measured error."""


def fit_shaper(transform: Callable[[torch.Tensor], torch.Tensor], *, knots: int = FIT_KNOTS, hdr: bool = True) -> tuple:
    """``(curve (knots, 3), curve_range)`` of a :class:`~torchgrade.lut.FittedShaper` for ``transform``.

    ``hdr=False`` fits from black to 1 instead of 65504.

    Examples:
        >>> import torch
        >>> curve, _ = fit_shaper(lambda image: image.clamp(0, 1), knots=16, hdr=False)
        >>> bool((curve[1:] > curve[:-1]).all())
        True
    """
    top = HALF_MAX if hdr else 1.0
    curve_range = (float(linear_to_logc(torch.tensor(0.0, dtype=torch.float64))),
                   float(linear_to_logc(torch.tensor(top, dtype=torch.float64))))
    logc = torch.linspace(*curve_range, knots, dtype=torch.float64)
    sweep = logc_to_linear(logc).clamp(0.0, top)
    bases = _base_colours(hdr)
    with torch.no_grad():
        bend = torch.stack([_bend(transform, bases, sweep, channel) for channel in range(3)], dim=1)
    return _curve(bend.sqrt()), curve_range


def _curve(density: torch.Tensor) -> torch.Tensor:
    """The shaper curve ``(knots, 3)`` of a lattice density per interval ``(knots - 1, 3)``, with the :data:`FIT_FLOOR` share even."""
    density = (1.0 - FIT_FLOOR) * density / density.sum(0).clamp_min(1e-12) + FIT_FLOOR / density.shape[0]
    curve = torch.cat((torch.zeros(1, 3, dtype=density.dtype), density.cumsum(0)))
    return curve / curve[-1]


def refine_shaper(curve: torch.Tensor, curve_range, bake: Callable, colours: torch.Tensor, errors_of: Callable,
                  rounds: int = FIT_ROUNDS) -> torch.Tensor:
    """Move a fitted curve's lattice planes toward the LogC bands where the baked LUT's error is largest.

    ``bake(curve)`` bakes a LUT with the curve; ``errors_of(lut)`` gives its error per colour of
    ``colours`` ``(3, N)`` (8-bit codes, worst channel). Each round scales the lattice density of
    every band by the square root of its worst error over the median band's; the curve with the
    lowest max error is returned.

    Examples:
        >>> import torch
        >>> curve = torch.linspace(0.0, 1.0, 5).unsqueeze(1).repeat(1, 3)
        >>> same = refine_shaper(curve, (0.0, 1.0), lambda c: c, torch.rand(3, 8), lambda c: torch.zeros(8), rounds=1)
        >>> torch.equal(same, curve)
        True
    """
    knots = curve.shape[0]
    band = ((linear_to_logc(colours.clamp_min(0.0)) - curve_range[0]) / (curve_range[1] - curve_range[0])
            * FIT_BANDS).long().clamp(0, FIT_BANDS - 1)
    knot_band = (torch.arange(knots - 1, dtype=torch.float64) + 0.5) / (knots - 1) * FIT_BANDS
    best, best_error = curve, float("inf")
    for _ in range(rounds):
        errors = errors_of(bake(curve))
        score = float(errors.quantile(0.999))
        if score < best_error:
            best, best_error = curve, score
        if best_error <= 0.0:
            break
        worst = torch.stack([_band_quantiles(errors, row) for row in band])
        reference = worst[worst > 0].median() if bool((worst > 0).any()) else torch.tensor(1.0)
        gain = (worst / reference).clamp(0.25, 4.0).sqrt().where(worst > 0, torch.ones(()))
        density = (curve[1:] - curve[:-1]) * gain.t()[knot_band.long().clamp(max=FIT_BANDS - 1)]
        curve = _curve(density)
    return best


def _band_quantiles(errors: torch.Tensor, band: torch.Tensor) -> torch.Tensor:
    """99th percentile of ``errors`` per band index in ``band`` (0 for an empty band), ``(FIT_BANDS,)``."""
    order = band.argsort(stable=True)
    counts = torch.bincount(band, minlength=FIT_BANDS).tolist()
    return torch.stack([part.quantile(0.99) if part.numel() else part.new_zeros(())
                        for part in errors[order].split(counts)])


def _base_colours(hdr: bool) -> torch.Tensor:
    """``(3, FIT_BASES)`` validation colours whose channels are swept."""
    colours = validation_colours(hdr)
    return colours[:, torch.linspace(0, colours.shape[1] - 1, FIT_BASES).long()]


def _bend(transform, bases: torch.Tensor, sweep: torch.Tensor, channel: int) -> torch.Tensor:
    """Largest ``|second difference|`` of the display codes as ``channel`` sweeps, per sweep interval ``(knots - 1,)``."""
    colours = bases.t().unsqueeze(1).repeat(1, sweep.numel(), 1)  # (bases, knots, 3)
    colours[..., channel] = sweep
    image = colours.permute(2, 0, 1).unsqueeze(0)  # (1, 3, bases, knots)
    output = transform(image)
    codes = 255.0 * linear_to_srgb(output.double())[0]  # unclipped: a display LUT clips after its lookup
    second = (codes[..., 2:] - 2.0 * codes[..., 1:-1] + codes[..., :-2]).abs().amax(dim=0).mean(0)
    # a bend at an inner knot is shared by the two intervals beside it
    padded = torch.nn.functional.pad(second, (1, 1))
    return torch.maximum(padded[:-1], padded[1:])


SCENE_KNOTS = 2048
"""Points of a scene-fitted shaper's curve (LogC-spaced from black to the top): fine enough that planes as close as the
rounds usually move them (a fraction of a stop) still fall on distinct points."""

SCENE_MIN_SIZE = 4
"""Smallest lattice :func:`start_planes` lays out: an interval below ``T``, one to the scene's top, one to 65504."""

SCENE_ROUNDS = 6
"""Bake-and-fit rounds of :func:`fit_scene_shaper` (each fits a table's entries: seconds at 33³)."""

SCENE_OFFSET = 0.03
"""``c`` of the start's ``log2(x + c)`` spacing: a little more even in the shadows than LogC's 0.0094."""

SCENE_TOP_QUANTILE = 0.999
"""Quantile of a channel over the scene that sets the start's top ``T``."""

SCENE_TOP_SCALE = 4.0
"""``T`` over the :data:`SCENE_TOP_QUANTILE` quantile: the scene's rarer, brighter pixels share the last interval."""

SCENE_GAIN = (0.5, 2.0)
"""``(low, high)`` bounds on an interval's gain: one round narrows an interval by at most ``high`` and widens it by at
most ``1 / low``."""

SCENE_FIT_WEIGHT = 1e4
"""Weight of a scene pixel (beside a validation colour or a lattice point's 1) when the entries of a table on a
scene-fitted lattice are fitted: its last interval, from ``T`` to 65504, holds validation colours everywhere, whose
errors would otherwise bound how closely the fit serves the scene (benchmarks/results/lut_fit.md)."""


def _log_offset(x: torch.Tensor) -> torch.Tensor:
    return torch.log2(x.clamp_min(0.0) + SCENE_OFFSET)


def start_planes(pixels: torch.Tensor, size: int, hdr: bool = True) -> torch.Tensor:
    """Linear positions ``(size, 3)`` of the start lattice's planes for a scene's ``pixels`` ``(3, N)`` (module docstring).

    ``T`` is at least one even interval above black, so a channel the scene leaves dark still spans colours near it.

    Examples:
        >>> import torch
        >>> pixels = torch.rand(3, 10000, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 4
        >>> pixels[0, 0] = 100.0  # one bright pixel: its own interval, below the one to the top
        >>> planes = start_planes(pixels, size=9)
        >>> planes.shape, float(planes[0, 0]), round(float(planes[-2, 0]), 6), float(planes[-1, 0]), bool(planes[-3, 0] <= 16)
        (torch.Size([9, 3]), 0.0, 100.0, 65504.0, True)
    """
    if size < SCENE_MIN_SIZE:
        raise ValueError(f"a lattice fitted to a scene needs size >= {SCENE_MIN_SIZE} (black to T, T to the scene's top, "
                         f"on to 65504), got {size}")
    top = HALF_MAX if hdr else 1.0
    pixels = pixels.double().clamp(0.0, top)
    sample = pixels[:, :: max(1, pixels.shape[1] // (1 << 16))]  # quantile takes at most 2^24 values; 2^16 suffice
    largest = pixels.amax(dim=1)
    black = _log_offset(torch.zeros((), dtype=torch.float64))
    ceiling = _log_offset(torch.tensor(top, dtype=torch.float64))
    even = (ceiling - black) / (size - 1)  # an interval's width when the planes are even to the top
    high = _log_offset(torch.minimum(SCENE_TOP_SCALE * sample.quantile(SCENE_TOP_QUANTILE, dim=1), largest))
    high = high.clamp(black + even, ceiling - 2 * even)
    steps = torch.linspace(0.0, 1.0, size - 2, dtype=torch.float64).unsqueeze(1)
    dense = black + steps * (high - black)
    width = (high - black) / (size - 3)
    scene_top = torch.maximum(_log_offset(largest), high + width).clamp_max(ceiling - even)
    planes = torch.cat((dense, scene_top.unsqueeze(0))).exp2() - SCENE_OFFSET
    planes[0] = 0.0
    return torch.cat((planes, torch.full((1, 3), top, dtype=torch.float64)))


def move_planes(planes: torch.Tensor, pixels: torch.Tensor, errors: torch.Tensor, step: float = 1.0) -> torch.Tensor:
    """One equidistribution step: the intervals below the last resized by the errors ``(N,)`` of ``pixels`` ``(3, N)``.

    Per channel, an interval ``k`` is resized in ``log2(x + c)`` by ``g_k^(-step)``, ``g_k = (E_k / median E)^(1/2)``
    (``E_k`` the largest error of a pixel in it, those above counting in the highest; clamped to :data:`SCENE_GAIN`),
    since linear interpolation misses a smooth curve by ``h² |f''| / 8``; an interval no pixel falls in widens by
    ``1 / low``.

    Examples:
        >>> import torch
        >>> planes = torch.tensor([[0.0], [1.0], [2.0], [3.0], [9.0]], dtype=torch.float64).expand(5, 3)
        >>> pixels = torch.tensor([[0.5, 1.5, 2.5]], dtype=torch.float64).expand(3, 3)
        >>> moved = move_planes(planes, pixels, torch.tensor([4.0, 1.0, 1.0], dtype=torch.float64))
        >>> bool(moved[1, 0] - moved[0, 0] < 1.0), round(float(moved[3, 0]), 9), float(moved[4, 0])  # the worst narrows
        (True, 3.0, 9.0)
    """
    inner = planes.shape[0] - 2
    moved = planes.clone()
    for channel in range(3):
        edges = planes[: inner + 1, channel].contiguous()
        interval = (torch.searchsorted(edges, pixels[channel].contiguous(), right=True) - 1).clamp(0, inner - 1)
        worst = torch.zeros(inner, dtype=torch.float64).scatter_reduce(0, interval, errors.double(), "amax")
        seen = worst > 0
        reference = worst[seen].median() if bool(seen.any()) else torch.ones((), dtype=torch.float64)
        gain = (worst / reference).sqrt().clamp(*SCENE_GAIN).where(seen, torch.tensor(SCENE_GAIN[0], dtype=torch.float64)) ** step
        logs = _log_offset(edges)
        widths = (logs[1:] - logs[:-1]) / gain
        spread = torch.cat((torch.zeros(1, dtype=torch.float64), widths.cumsum(0))) / widths.sum()
        moved[: inner + 1, channel] = (logs[0] + spread * (logs[-1] - logs[0])).exp2() - SCENE_OFFSET
        moved[0, channel] = 0.0
    return moved


def planes_curve(planes: torch.Tensor, hdr: bool = True, knots: int = SCENE_KNOTS) -> tuple:
    """``(curve (knots, 3), curve_range)`` of a :class:`~torchgrade.lut.FittedShaper` whose lattice planes lie at
    ``planes`` ``(S, 3)`` (linear, from black to the top): lattice coordinate ``k / (S - 1)`` at plane ``k``, linear
    in LogC codes between planes.

    Examples:
        >>> import torch
        >>> planes = torch.tensor([0.0, 0.18, 1.0], dtype=torch.float64).unsqueeze(1).expand(3, 3)
        >>> curve, curve_range = planes_curve(planes, hdr=False, knots=5)
        >>> curve.shape, float(curve[0, 0]), float(curve[-1, 0])
        (torch.Size([5, 3]), 0.0, 1.0)
    """
    top = HALF_MAX if hdr else 1.0
    low, high = (float(linear_to_logc(torch.tensor(v, dtype=torch.float64))) for v in (0.0, top))
    grid = torch.linspace(low, high, knots, dtype=torch.float64)
    coordinates = torch.linspace(0.0, 1.0, planes.shape[0], dtype=torch.float64)
    columns = []
    for channel in range(3):
        logc = linear_to_logc(planes[:, channel].double())
        upper = torch.searchsorted(logc, grid, right=True).clamp(1, logc.numel() - 1)
        fraction = ((grid - logc[upper - 1]) / (logc[upper] - logc[upper - 1])).clamp(0.0, 1.0)
        columns.append(coordinates[upper - 1] + fraction * (coordinates[upper] - coordinates[upper - 1]))
    return torch.stack(columns, dim=1), (low, high)


def fit_scene_shaper(fit: Callable, pixels: torch.Tensor, errors_of: Callable, size: int, hdr: bool = True,
                     rounds: int = SCENE_ROUNDS, progress: bool = False) -> tuple:
    """``(curve, curve_range)`` of the lattice, of ``rounds`` moved by the errors, whose fitted table misses least.

    ``fit(curve, curve_range)`` bakes a LUT on a curve and fits its entries to the scene; ``errors_of(lut)`` gives its
    error per pixel of ``pixels`` ``(3, N)`` (8-bit codes, worst channel). ``progress`` shows a bar over the rounds.

    Examples:
        >>> import torch
        >>> pixels = torch.rand(3, 100, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
        >>> curve, curve_range = fit_scene_shaper(lambda *c: c, pixels, lambda lut: pixels[0], size=5, rounds=2)
        >>> curve.shape, bool((curve[1:] > curve[:-1]).all())
        (torch.Size([2048, 3]), True)
    """
    pixels = pixels.double()
    planes = start_planes(pixels, size, hdr)
    best = None
    step = 1.0
    for _ in tqdm(range(rounds), desc=f"fitting a {size}³ lattice to the scene", unit="round",
                  disable=None if progress else True, leave=False):
        if best is not None:
            planes = move_planes(best[0], pixels, best[2], step)
        curve = planes_curve(planes, hdr)
        errors = errors_of(fit(*curve))
        if best is None or float(errors.max()) < float(best[2].max()):
            best = (planes, curve, errors)
        else:
            step /= 2
    if best is None:
        raise ValueError(f"rounds must be at least 1, got {rounds}")
    return best[1]
