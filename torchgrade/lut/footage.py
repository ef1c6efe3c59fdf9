"""The footage a baked LUT's report stands for, beyond natural daylight: colour charts and warm practicals.

The realistic colours (:func:`~torchgrade.lut.validation.realistic_colours`) are natural footage: their chroma is
spread as the sample photographs' is, so they hold few of a colour chart's saturated patches and few of the deep
oranges a candle or a tungsten bulb casts, where a grade's LUT misses most (the cinematic look's default bake: 1.52
codes on the realistic colours, several codes on a chart or a candle-lit still life). The report measures two more
sets and names each (:class:`~torchgrade.lut.ErrorReport`'s ``footage``):

* **colour charts** (:func:`chart_colours`): the 24 patches of the ColorChecker Classic (:data:`COLORCHECKER_LAB`),
  in linear Rec.709, exposed within :data:`CHART_STOPS` of their published values;
* **warm practicals** (:func:`warm_colours`): lights on the Planckian locus between :data:`WARM_CCTS` kelvin (a
  candle flame to a tungsten bulb), as bright as :data:`LIGHT_STOPS` says, and natural surfaces (realistic colours)
  lit by them, as a camera balanced for daylight (D65) records them.

Examples:
    >>> chart_colours().shape, warm_colours().shape
    (torch.Size([3, 6168]), torch.Size([3, 8192]))
"""

from __future__ import annotations

import torch

from ..color.spaces import MATRICES, REC709_CHROMATICITIES, bradford_adaptation
from .validation import realistic_colours

__all__ = ["COLORCHECKER_LAB", "D50", "CHART_STOPS", "CHART_STEPS", "CHART_COLOURS", "WARM_CCTS", "LIGHT_STOPS", "WARM_COLOURS",
           "LIGHT_SHARE", "CHART", "WARM",
           "colorchecker_rec709", "planckian_rec709", "chart_colours", "warm_colours", "footage_colours"]

COLORCHECKER_LAB = (
    (37.54, 14.37, 14.92), (64.66, 19.27, 17.50), (49.32, -3.82, -22.54), (43.46, -12.74, 22.72),
    (54.94, 9.61, -24.79), (70.48, -32.26, -0.37), (62.73, 35.83, 56.50), (39.43, 10.75, -45.17),
    (50.57, 48.64, 16.67), (30.10, 22.54, -20.87), (71.77, -24.13, 58.19), (71.51, 18.24, 67.37),
    (28.37, 15.42, -49.80), (54.38, -39.72, 32.27), (42.43, 51.05, 28.62), (81.80, 2.67, 80.41),
    (50.63, 51.28, -14.12), (49.57, -29.71, -28.32), (95.19, -1.03, 2.93), (81.29, -0.57, 0.44),
    (66.89, -0.75, -0.06), (50.76, -0.13, 0.14), (35.63, -0.46, -0.48), (20.64, 0.07, -0.46),
)
"""The ColorChecker Classic's 24 patches in chart order (dark skin ... black), CIE L*a*b* under D50 (2°): X-Rite's
values for charts made from November 2014, as colour-science publishes them
(``colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]``)."""

D50 = (0.34570, 0.35850)
"""The chart's white (CIE 1931 xy of D50, ICC's): its values are adapted from it to Rec.709's D65 (Bradford)."""

CHART_STOPS = (-4.0, 4.0)
"""A chart's exposure in stops about its published values (grey patch at 19 %): a chart is shot exposed for the scene."""

CHART_STEPS = 32
"""Exposures per stop of the chart colours: every patch at every 1/32 stop over :data:`CHART_STOPS` (its p99.9 on the
cinematic look moves by 0.05 codes from 1/32 to 1/64 stop, by 0.6 from 1/8 to 1/16: errors peak within fractions of a
stop)."""

CHART_COLOURS = 24 * (round(CHART_STEPS * (CHART_STOPS[1] - CHART_STOPS[0])) + 1)
"""Chart colours the report measures (6,168)."""

WARM_CCTS = (1800.0, 2700.0)
"""The warm practicals' colour temperatures, kelvin: a candle flame to a household tungsten bulb."""

LIGHT_STOPS = (2.5, 12.0)
"""A practical's luminance in stops about 18 % grey: from linear 1 (no surface it lights is brighter than the light
itself, and a scene is exposed for those surfaces, white at about 1) up to 737."""

WARM_COLOURS = 8192
"""Warm practicals the report measures: lights (:data:`LIGHT_SHARE` of them) and surfaces lit by them."""

LIGHT_SHARE = 0.25
"""The share of the warm practicals that are the lights themselves; the rest are surfaces lit by them."""

CHART = "colour charts"
"""How a report names :func:`chart_colours`."""

WARM = "warm practicals"
"""How a report names :func:`warm_colours`."""


def colorchecker_rec709() -> torch.Tensor:
    """The 24 patches of :data:`COLORCHECKER_LAB` in linear Rec.709 (D65), ``(3, 24)`` float64: CIE L*a*b* -> XYZ
    (CIE 15:2004, white D50), Bradford to D65, XYZ -> Rec.709. The cyan patch lies outside Rec.709 (red below 0).

    Examples:
        >>> patches = colorchecker_rec709()
        >>> [round(v, 2) for v in patches[:, 21].tolist()]  # neutral 5: grey, Y 0.19
        [0.19, 0.19, 0.19]
    """
    lab = torch.tensor(COLORCHECKER_LAB, dtype=torch.float64).t()
    fy = (lab[0] + 16.0) / 116.0
    f = torch.stack((fy + lab[1] / 500.0, fy, fy - lab[2] / 200.0))
    epsilon, kappa = 216.0 / 24389.0, 24389.0 / 27.0
    relative = torch.where(f ** 3 > epsilon, f ** 3, (116.0 * f - 16.0) / kappa)
    white = torch.tensor((D50[0] / D50[1], 1.0, (1.0 - D50[0] - D50[1]) / D50[1]), dtype=torch.float64)
    xyz = relative * white.reshape(3, 1)
    return MATRICES["xyz_to_rec709"] @ bradford_adaptation(D50, REC709_CHROMATICITIES[3]) @ xyz


def planckian_rec709(kelvin: torch.Tensor) -> torch.Tensor:
    """Linear Rec.709 of the Planckian (black body) light at ``kelvin`` (1667 to 4000 K), luminance 1, ``(3, N)``
    float64, unadapted (a camera balanced for D65): its CIE 1931 xy from Kang et al. (2002)'s cubic fit of the
    Planckian locus (within 0.001 of the black body's xy over this range). Below about 1900 K blue is negative: the
    light lies outside Rec.709.

    Examples:
        >>> [round(v, 2) for v in planckian_rec709(torch.tensor([2700.0])).flatten().tolist()]
        [1.93, 0.81, 0.19]
    """
    t = kelvin.double()
    x = -0.2661239e9 / t ** 3 - 0.2343589e6 / t ** 2 + 0.8776956e3 / t + 0.179910
    cool = -0.9549476 * x ** 3 - 1.37418593 * x ** 2 + 2.09137015 * x - 0.16748867
    warm = -1.1063814 * x ** 3 - 1.34811020 * x ** 2 + 2.18555832 * x - 0.20219683
    y = torch.where(t <= 2222.0, warm, cool)
    xyz = torch.stack((x / y, torch.ones_like(x), (1.0 - x - y) / y))
    return MATRICES["xyz_to_rec709"] @ xyz


def chart_colours() -> torch.Tensor:
    """The chart colours, ``(3, CHART_COLOURS)`` float64: every patch of :func:`colorchecker_rec709` times ``2^s`` for
    ``s`` every ``1 / CHART_STEPS`` stop over :data:`CHART_STOPS`.

    Examples:
        >>> colours = chart_colours()
        >>> colours.shape[1] == CHART_COLOURS, torch.equal(colours[:, :24] * 256, colours[:, -24:])
        (True, True)
    """
    low, high = CHART_STOPS
    stops = torch.linspace(low, high, CHART_COLOURS // 24, dtype=torch.float64)
    return (colorchecker_rec709().unsqueeze(1) * stops.exp2().unsqueeze(1)).reshape(3, -1)


def warm_colours(seed: int = 0) -> torch.Tensor:
    """The warm practicals, ``(3, WARM_COLOURS)`` float64, the same on every call: at a colour temperature drawn
    uniformly over :data:`WARM_CCTS` (kelvin), the light (:func:`planckian_rec709`) at ``0.18 · 2^s``, ``s`` uniform
    over :data:`LIGHT_STOPS`, or a natural surface lit by it: a realistic colour (drawn with seed ``seed + 1``) times
    the light per channel, a von Kries stand-in for the product of their spectra.

    Examples:
        >>> colours = warm_colours()
        >>> float((colours[0] > colours[2]).double().mean()) > 0.9  # red above blue: warm
        True
    """
    generator = torch.Generator().manual_seed(seed)

    def uniform(count: int, bounds: tuple) -> torch.Tensor:
        return bounds[0] + (bounds[1] - bounds[0]) * torch.rand(count, generator=generator, dtype=torch.float64)

    light = planckian_rec709(uniform(WARM_COLOURS, WARM_CCTS))
    lights = int(LIGHT_SHARE * WARM_COLOURS)
    lamps = 0.18 * uniform(lights, LIGHT_STOPS).exp2().expand(3, lights)
    surfaces = realistic_colours(seed=seed + 1)[:, : WARM_COLOURS - lights]
    return light * torch.cat((lamps, surfaces), dim=1)


def footage_colours() -> dict:
    """``{name: (3, N) float64}``: the footage the report names beside the realistic colours, :data:`CHART` and
    :data:`WARM`.

    Examples:
        >>> list(footage_colours())
        ['colour charts', 'warm practicals']
    """
    return {CHART: chart_colours(), WARM: warm_colours()}
