"""The colours a baked LUT is measured on: realistic ones for its headline error, and validation colours
covering the whole domain for its worst case.

**Realistic colours** (:func:`realistic_colours`): what a frame holds. Luminance log-uniform over
``REALISTIC_STOPS`` (-12 to +8) around 18 % grey: the 1st and 99th percentiles of log2(Y / 0.18) over
the five natural sample images (CandleGlass, Carrots, Desk, Garden, GoldenGate, pooled) are -12.4
and +7.6; log-uniform because a frame's exposure is not known, so every level in that range is as
likely to hold the worst pixels. Chroma: per-channel log-normal ratios with ``CHROMA_SIGMA`` = 0.5,
which spreads ln(R / B) by 0.70, the median of the four colour images' 0.48 / 0.63 / 0.77 / 1.11
(pixels above each image's 10th luminance percentile). No negative values and no highlights above
linear 46 in luminance: those belong to the worst case. ``benchmarks/lut_realistic.py`` compares the error
on these colours with the error measured on the sample images.

**Validation colours** (:func:`validation_colours`), the worst case, in three parts, concatenated as ``(3, N)``
float64 linear Rec.709 values:

* **footage**: luminance drawn as real footage spreads it, log-normal around 18 % grey (2.5 stops
  standard deviation), with a tail drawn log-uniformly up to the half-float top (65504); chroma from
  per-channel log-normal ratios, so most colours are moderately saturated and some are extreme;
* **out of gamut**: a tenth of the footage colours with one channel negative (wide-gamut sources
  converted to Rec.709 have them);
* **gamut grid**: every combination of ``GRID_LEVELS`` levels per channel, evenly spaced in LogC
  from black to the top: primaries, secondaries and greys at every intensity.

An LDR transform (one that takes [0, 1] input) is measured on the same constructions with the top at 1.

**Bright saturated colours** (:func:`bright_saturated_colours`): the highlights a lattice reaching 65504 must keep
(lamps, the sun, speculars, saturated emissives): one channel from the LogC top (58.86) to 65504 in
``HIGHLIGHT_STEPS`` log-spaced levels, each of the other two a fraction of it (0, 1e-4, ... 0.3), in every order.

Examples:
    >>> colours = validation_colours()
    >>> colours.shape[0], float(colours.max()) == 65504.0
    (3, True)
"""

from __future__ import annotations

import itertools
import math

import torch

from ..base.images import HALF_MAX
from ..color import linear_to_logc, logc_to_linear
from ..color.spaces import REC709_LUMINANCE
from .shapers import LOGC_TOP

__all__ = ["validation_colours", "realistic_colours", "bright_saturated_colours", "FOOTAGE_COLOURS", "GRID_LEVELS",
           "REALISTIC_COLOURS", "REALISTIC_STOPS", "CHROMA_SIGMA", "HIGHLIGHT_STEPS", "HIGHLIGHT_FRACTIONS"]

HIGHLIGHT_STEPS = 64
"""Levels of the bright channel of :func:`bright_saturated_colours`, log-spaced from 58.86 to 65504."""

HIGHLIGHT_FRACTIONS = (0.0, 1e-4, 1e-3, 3e-3, 0.01, 0.03, 0.1, 0.3)
"""The other channels of a bright saturated colour, as fractions of its bright channel."""

FOOTAGE_COLOURS = 16384
"""Footage-like colours in the validation set (the gamut grid adds ``GRID_LEVELS ** 3``)."""

GRID_LEVELS = 9
"""Levels per channel of the gamut grid (LogC-spaced; 0 and the top included)."""

REALISTIC_COLOURS = 16384
"""Realistic colours a LUT's headline error is measured on."""

REALISTIC_STOPS = (-12.0, 8.0)
"""Range of the realistic colours' luminance, in stops around 18 % grey (linear 4.4e-5 to 46)."""

CHROMA_SIGMA = 0.5
"""Standard deviation of the realistic colours' natural-log channel ratios."""


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


def bright_saturated_colours() -> torch.Tensor:
    """Bright saturated colours, ``(3, N)`` float64: see the module docstring.

    Examples:
        >>> colours = bright_saturated_colours()
        >>> colours.shape, float(colours.max()) == 65504.0, float(colours.min())
        (torch.Size([3, 24576]), True, 0.0)
    """
    bright = torch.logspace(math.log10(LOGC_TOP), math.log10(HALF_MAX), HIGHLIGHT_STEPS, dtype=torch.float64)
    bright[0], bright[-1] = LOGC_TOP, HALF_MAX  # the ends exactly
    fractions = torch.tensor(HIGHLIGHT_FRACTIONS, dtype=torch.float64)
    second, third = torch.meshgrid(fractions, fractions, indexing="ij")
    colours = torch.stack(torch.broadcast_tensors(bright[:, None], bright[:, None] * second.flatten(), bright[:, None] * third.flatten()))
    colours = colours.reshape(3, -1)
    return torch.cat([colours[list(order)] for order in itertools.permutations(range(3))], dim=1)


def realistic_colours(hdr: bool = True, seed: int = 0) -> torch.Tensor:
    """The realistic colours, ``(3, REALISTIC_COLOURS)`` float64: see the module docstring; the same on every call.

    ``Y = 0.18 * 2 ** U(REALISTIC_STOPS)``, ``rgb = r / (w · r) * Y`` with ``ln r ~ N(0, CHROMA_SIGMA²)`` per channel
    and ``w`` Rec.709's luminance weights. An LDR transform's (``hdr=False``) stop at luminance 1 (the range's top
    lowered to log2(1 / 0.18) stops) and are clamped to [0, 1].

    Examples:
        >>> colours = realistic_colours()
        >>> weights = torch.tensor([0.2126729, 0.7151522, 0.0721750], dtype=torch.float64)
        >>> luminance = weights @ colours
        >>> bool(luminance.min() >= 0.18 * 2 ** -12), bool(luminance.max() <= 0.18 * 2 ** 8), bool((colours >= 0).all())
        (True, True, True)
        >>> float(realistic_colours(hdr=False).max())
        1.0
    """
    generator = torch.Generator().manual_seed(seed)
    low, high = REALISTIC_STOPS
    high = high if hdr else math.log2(1.0 / 0.18)
    stops = low + (high - low) * torch.rand(REALISTIC_COLOURS, generator=generator, dtype=torch.float64)
    ratios = torch.exp(CHROMA_SIGMA * torch.randn(3, REALISTIC_COLOURS, generator=generator, dtype=torch.float64))
    weights = torch.tensor(REC709_LUMINANCE, dtype=torch.float64).reshape(3, 1)
    colours = ratios / (weights * ratios).sum(0) * 0.18 * stops.exp2()
    return colours if hdr else colours.clamp(max=1.0)


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
