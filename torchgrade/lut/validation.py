"""The validation colours a baked LUT is measured on: deterministic, footage-like, gamut- and range-covering.

Three parts, concatenated as ``(3, N)`` float64 linear Rec.709 values:

* **footage**: luminance drawn as real footage spreads it, log-normal around 18 % grey (2.5 stops
  standard deviation), with a tail drawn log-uniformly up to the half-float top (65504); chroma from
  per-channel log-normal ratios, so most colours are moderately saturated and some are extreme;
* **out of gamut**: a tenth of the footage colours with one channel negative (wide-gamut sources
  converted to Rec.709 have them);
* **gamut grid**: every combination of ``GRID_LEVELS`` levels per channel, evenly spaced in LogC
  from black to the top: primaries, secondaries and greys at every intensity.

An LDR transform (one that takes [0, 1] input) is measured on the same construction with the top at 1.

Examples:
    >>> colours = validation_colours()
    >>> colours.shape[0], float(colours.max()) == 65504.0
    (3, True)
"""

from __future__ import annotations

import torch

from ..base.core import HALF_MAX
from ..color import linear_to_logc, logc_to_linear

__all__ = ["validation_colours", "FOOTAGE_COLOURS", "GRID_LEVELS"]

FOOTAGE_COLOURS = 16384
"""Footage-like colours in the validation set (the gamut grid adds ``GRID_LEVELS ** 3``)."""

GRID_LEVELS = 9
"""Levels per channel of the gamut grid (LogC-spaced; 0 and the top included)."""


def validation_colours(hdr: bool = True, seed: int = 0) -> torch.Tensor:
    """The validation set, ``(3, N)`` float64: see the module docstring; the same colours on every call.

    Examples:
        >>> torch.equal(validation_colours(False), validation_colours(False))
        True
    """
    generator = torch.Generator().manual_seed(seed)
    top = HALF_MAX if hdr else 1.0
    footage = _footage(generator, top)
    flipped = torch.rand(FOOTAGE_COLOURS, generator=generator) < 0.1
    channel = torch.randint(0, 3, (FOOTAGE_COLOURS,), generator=generator)
    negative = -0.2 * torch.rand(FOOTAGE_COLOURS, generator=generator, dtype=torch.float64) * footage.mean(0)
    footage[channel[flipped], flipped.nonzero().flatten()] = negative[flipped]
    return torch.cat((footage, _gamut_grid(top)), dim=1)


def _footage(generator: torch.Generator, top: float) -> torch.Tensor:
    """Footage-like colours: log-normal luminance (a log-uniform tail to ``top``), log-normal channel ratios."""
    count = FOOTAGE_COLOURS
    stops = torch.randn(count, generator=generator, dtype=torch.float64) * 2.5 + torch.log2(torch.tensor(0.18))
    tail = torch.rand(count, generator=generator) < 0.1
    tail_stops = torch.rand(count, generator=generator, dtype=torch.float64) * 28.0 - 14.0  # 2^-14 .. 2^14
    luminance = torch.where(tail, tail_stops, stops).exp2()
    ratios = torch.exp(torch.randn(3, count, generator=generator, dtype=torch.float64) * 0.6)
    colours = ratios / ratios.mean(0) * luminance
    return colours.clamp(max=top)


def _gamut_grid(top: float) -> torch.Tensor:
    """``GRID_LEVELS³`` colours on a LogC-spaced grid from 0 to ``top``, ``(3, GRID_LEVELS³)``."""
    bottom, high = (float(linear_to_logc(torch.tensor(v, dtype=torch.float64))) for v in (0.0, top))
    levels = logc_to_linear(torch.linspace(bottom, high, GRID_LEVELS, dtype=torch.float64))
    levels[0], levels[-1] = 0.0, top  # exact ends despite the round trip
    r, g, b = torch.meshgrid(levels, levels, levels, indexing="ij")
    return torch.stack((r.flatten(), g.flatten(), b.flatten()))
