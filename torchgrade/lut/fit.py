"""Fitting a LUT's per-channel shaper to its transform: lattice planes where the picture bends.

Linear interpolation between lattice points spaced ``h`` apart misses a curve by about ``h² |f''| / 8``,
so the max error is smallest when ``h`` shrinks as ``1 / sqrt|f''|``: the lattice density along each
channel follows ``sqrt|f''|`` (error equidistribution). :func:`fit_shaper` measures ``f''`` in what a
viewer sees (8-bit sRGB display codes) along each input channel in LogC code space, from black to the
half-float top, sweeping that channel of a set of base colours (validation colours, and the scene's
pixels when given), and takes the largest bend over output channels, averaged over base colours. A
floor keeps a share of the lattice everywhere, so colours the fit did not see are still covered.

A 3D table's error also comes from bends across channels (saturation, a ``max(0, ·)`` on an oblique
surface), which one-channel sweeps do not see: :func:`refine_shaper` then bakes the table, measures
it, and moves lattice planes toward the LogC bands where the error is largest, a few rounds.

The result is the curve of a :class:`~torchgrade.lut.FittedShaper`.

Examples:
    >>> import torch
    >>> curve, curve_range = fit_shaper(lambda image: image / (1 + image), knots=32)
    >>> curve.shape, float(curve[0, 0]), float(curve[-1, 0])
    (torch.Size([32, 3]), 0.0, 1.0)
"""

from __future__ import annotations

from typing import Callable, Optional

import torch

from ..color import linear_to_logc, linear_to_srgb, logc_to_linear
from ..core import HALF_MAX, check_image, sanitize
from .validation import validation_colours

__all__ = ["fit_shaper", "refine_shaper", "FIT_KNOTS", "FIT_BASES", "FIT_FLOOR", "FIT_ROUNDS", "FIT_BANDS"]

FIT_KNOTS = 512
"""Points of a fitted shaper's curve (LogC-spaced from black to 65504)."""

FIT_BASES = 96
"""Base colours swept per channel (half validation colours, half scene pixels when a scene is given)."""

FIT_FLOOR = 0.15
"""Share of the lattice spread evenly in LogC whatever the transform does (for colours the fit did not see)."""

FIT_ROUNDS = 4
"""Bake-and-measure rounds of :func:`refine_shaper`."""

FIT_BANDS = 64
"""LogC bands per channel over which :func:`refine_shaper` attributes the measured error."""


def fit_shaper(transform: Callable[[torch.Tensor], torch.Tensor], scene: Optional[torch.Tensor] = None,
               knots: int = FIT_KNOTS, hdr: bool = True) -> tuple:
    """``(curve (knots, 3), curve_range)`` of a :class:`~torchgrade.lut.FittedShaper` for ``transform``.

    ``scene`` (an image) adds its pixels to the base colours, so the lattice follows the colours the
    LUT will see. ``hdr=False`` fits from black to 1 instead of 65504.

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
    bases = _base_colours(scene, hdr)
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


def _base_colours(scene: Optional[torch.Tensor], hdr: bool) -> torch.Tensor:
    """``(3, FIT_BASES)`` colours whose channels are swept: validation colours, and scene pixels when given."""
    colours = validation_colours(hdr)
    from_scene = 0 if scene is None else FIT_BASES // 2
    picks = torch.linspace(0, colours.shape[1] - 1, FIT_BASES - from_scene).long()
    bases = [colours[:, picks]]
    if scene is not None:
        check_image(scene, "scene")
        pixels = sanitize(scene.detach().double()).movedim(-3, 0).reshape(3, -1)
        order = pixels.max(0).values.argsort()  # spread over the scene's range, brightest included
        bases.append(pixels[:, order[torch.linspace(0, order.numel() - 1, from_scene).long()]])
    return torch.cat(bases, dim=1)


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
