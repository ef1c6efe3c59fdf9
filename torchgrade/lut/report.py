"""A baked LUT's error report: how far its lookup is from the transform, why, and what would meet the tolerance.

:func:`~torchgrade.bake_lut` measures every LUT it bakes against the transform evaluated directly in
float64, in what a viewer sees: 8-bit sRGB display codes, p99.9 and max over every channel value, on
two sets of colours (:mod:`~torchgrade.lut.validation`):

* the **realistic colours**, what natural frames hold, and the scene's pixels when given, or every pixel of the user's
  own frames when given (``bake_lut(frames=)``): the headline figure, which the tolerance judges
  (``benchmarks/results/lut_realistic.md``: within 1.5x of the p99.9 pooled over the sample images);
* the **footage** the realistic colours hold few of, each figure named beside the headline (``ErrorReport.footage``;
  not with ``frames=``, which are the footage): saturated colour charts and warm practicals
  (:mod:`~torchgrade.lut.footage`), where a look's LUT can miss twice as much or more;
* the **validation colours** over the whole domain (up to 65504, out of gamut, the gamut's corners):
  the worst case, shown beside it (``ErrorReport.worst_case``);
* for a lattice that reaches 65504, the **bright saturated colours** (``ErrorReport.highlights``): their max
  error must stay within :data:`HIGHLIGHT_TOLERANCE` too, or the report is over its tolerance and says why.

Above the tolerance the report names the cause it found on the realistic colours:

* **lattice range**: the error comes from colours outside the lattice (clamped per channel, which
  changes their hue): within the range the LUT is within tolerance;
* **a kink within a cell**: doubling the lattice does not shrink the error fourfold, as it would
  for a smooth transform: the transform bends sharply between lattice points;
* **size**: the error falls as a smooth transform's does; a larger lattice meets it;

and the first bake of :data:`CANDIDATES` that meets the tolerance, or says that none does.

The default report of an HDR bake evaluates :data:`REPORT_COLOURS` colours directly in float64 and through the LUT
(16,384 realistic, 6,168 chart, 8,192 warm, 17,113 validation and, for a lattice reaching 65504, 24,576 bright
saturated colours): about half the lattice points of a bake at the default size. Highlights missed by more than
:data:`HIGHLIGHT_TOLERANCE` cost one bake twice as fine, a report over its tolerance the bakes its causes and advice
name (:func:`diagnose`); ``frames=`` adds every pixel of the frames.

Examples:
    >>> import torchgrade as tg
    >>> lut = tg.bake_lut(lambda image: image.clamp(0, 1) * 0.5, size=5)
    >>> lut.error_report.within, lut.error_report.worst_case.colour_set
    (True, 'validation colours over the whole domain')
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from typing import Callable, Optional

import torch

from ..base.images import HALF_MAX, sanitize
from ..color import linear_to_srgb
from .footage import CHART_COLOURS, WARM_COLOURS
from .shapers import SHAPERS
from .validation import FOOTAGE_COLOURS, GRID_LEVELS, HIGHLIGHT_FRACTIONS, HIGHLIGHT_STEPS, REALISTIC_COLOURS, bright_saturated_colours

__all__ = ["ErrorReport", "LUTAccuracyWarning", "code_errors", "measured_colours", "measure", "diagnose", "enforce",
           "SCENE_PIXELS", "KINK_RATIO", "CANDIDATES", "ADVICE_MAX_SIZE", "REALISTIC", "FRAMES", "WORST_CASE",
           "HIGHLIGHT_TOLERANCE", "HIGHLIGHT_ADVICE_MAX_SIZE", "worst_case", "highlights_report", "footage_reports",
           "measure_pixels", "PIXEL_CHUNK", "REPORT_COLOURS"]

REALISTIC = "realistic colours"
"""How a report names :func:`~torchgrade.lut.validation.realistic_colours`."""

FRAMES = "pixels of the given frames"
"""How a report names the frames given to :func:`~torchgrade.bake_lut` (``frames=``)."""

WORST_CASE = "validation colours over the whole domain"
"""How a report names :func:`~torchgrade.lut.validation.validation_colours`."""

SCENE_PIXELS = 65536
"""At most this many scene pixels (evenly strided) join the realistic colours; of ``frames=``, at most this many
(evenly strided) serve the diagnosis, while the report's p99.9 and max are over every pixel."""

PIXEL_CHUNK = 1 << 18
"""Pixels of ``frames=`` evaluated at a time (float64): beyond the errors it keeps (float32, one per channel value, as
many bytes as the frames themselves), the report's memory stays bounded."""

REPORT_COLOURS = (REALISTIC_COLOURS + CHART_COLOURS + WARM_COLOURS + FOOTAGE_COLOURS + GRID_LEVELS ** 3
                  + 6 * HIGHLIGHT_STEPS * len(HIGHLIGHT_FRACTIONS) ** 2)
"""Colours the default report of an HDR bake evaluates in float64 and looks up, without diagnosis: realistic, chart,
warm, validation and bright saturated colours (72,433)."""

KINK_RATIO = 2.5
"""Error ratio from ``S³`` to ``(2S-1)³`` below which the cause is a kink (a smooth transform gives about 4)."""


HIGHLIGHT_TOLERANCE = 2.0
"""The most a lattice reaching 65504 may miss a bright saturated colour by (8-bit codes, max) where a finer lattice
would hold them: the report is then over its tolerance, and says so (:func:`highlights_report`)."""


HIGHLIGHT_ADVICE_MAX_SIZE = 2 * (SHAPERS["logc_extended"].default_size - 1) + 1
"""The largest lattice :func:`highlights_report` bakes to see whether a finer one holds the highlights (the default
lattice with twice its intervals, 101³)."""


class LUTAccuracyWarning(UserWarning):
    """A baked LUT misses its transform by more than the tolerance (see :class:`ErrorReport`)."""


@dataclass(frozen=True)
class ErrorReport:
    """A LUT's error against its transform, 8-bit sRGB display codes, on ``colours`` colours of ``colour_set``;
    ``worst_case`` the same on the validation colours over the whole domain.

    Examples:
        >>> worst = ErrorReport(9.0, 30.0, 200, 1.0, colour_set=WORST_CASE)
        >>> print(ErrorReport(0.4, 2.0, 100, 1.0, colour_set=REALISTIC, worst_case=worst))
        p99.9 0.40, max 2.00 8-bit codes on 100 realistic colours (tolerance 1 at p99.9); worst case: p99.9 9.00, max 30.00 on 200 validation colours over the whole domain
    """

    p99_9: float
    max: float
    colours: int
    tolerance: float
    cause: Optional[str] = None
    advice: Optional[str] = None
    worst_case: Optional["ErrorReport"] = None
    colour_set: str = "validation colours"
    highlights: Optional["ErrorReport"] = None
    """The max error on bright saturated colours (:func:`highlights_report`), for a lattice that reaches 65504."""
    binding: bool = True
    """Whether this report's tolerance judges the bake (a highlights report is not where no finer lattice helps)."""
    footage: tuple = ()
    """The same figures on the footage the realistic colours hold few of (:func:`footage_reports`: colour charts,
    warm practicals), each an :class:`ErrorReport` named by its ``colour_set``; shown, not judged."""

    @property
    def within(self) -> bool:
        """Whether the p99.9 error is within the tolerance, and the highlights' max within theirs where that binds."""
        high = self.highlights
        return self.p99_9 <= self.tolerance and (high is None or not high.binding or high.max <= high.tolerance)

    def __str__(self) -> str:
        text = (f"p99.9 {self.p99_9:.2f}, max {self.max:.2f} 8-bit codes on {self.colours} {self.colour_set} "
                f"(tolerance {self.tolerance:g} at p99.9)")
        for kind in self.footage:
            text += f"; on {kind.colour_set}: p99.9 {kind.p99_9:.2f}, max {kind.max:.2f} on {kind.colours}"
        if self.worst_case is not None:
            worst = self.worst_case
            text += f"; worst case: p99.9 {worst.p99_9:.2f}, max {worst.max:.2f} on {worst.colours} {worst.colour_set}"
            text += f" ({worst.cause})" if worst.cause else ""
        if self.highlights is not None:
            high = self.highlights
            text += f"; highlights: max {high.max:.2f} on {high.colours} {high.colour_set} (tolerance {high.tolerance:g})"
            text += f" ({high.cause})" if high.cause else ""
        if self.cause:
            text += f"; cause: {self.cause}"
        if self.advice:
            text += f"; {self.advice}"
        return text


def code_errors(reference: torch.Tensor, approximation: torch.Tensor) -> torch.Tensor:
    """``255 |srgb(clamp(a, 0, 1)) - srgb(clamp(b, 0, 1))|`` per value, float64, same shape.

    Examples:
        >>> import torch
        >>> [round(v, 6) for v in code_errors(torch.ones(2), torch.zeros(2)).tolist()]
        [255.0, 255.0]
    """
    codes = [255.0 * linear_to_srgb(t.detach().double().clamp(0.0, 1.0)) for t in (reference, approximation)]
    return (codes[0] - codes[1]).abs()


def _quantile(errors: torch.Tensor, quantile: float = 0.999) -> float:
    flat = errors.flatten()
    return float(flat.kthvalue(max(1, math.ceil(quantile * flat.numel()))).values) if flat.numel() else 0.0


def measured_colours(transform, colours: torch.Tensor, scene: Optional[torch.Tensor]) -> tuple:
    """``(colours (1, 3, 1, N) float64, reference output)``: ``colours`` ``(3, M)`` and at most :data:`SCENE_PIXELS`
    of the scene's pixels, and the transform on them."""
    if scene is not None:
        pixels = sanitize(scene.detach().double()).movedim(-3, 0).reshape(3, -1)
        colours = torch.cat((colours, pixels[:, :: max(1, pixels.shape[1] // SCENE_PIXELS)]), dim=1)
    image = colours.reshape(1, 3, 1, -1)
    with torch.no_grad():
        return image, transform(image).double()


def measure(lut, measured: tuple, tolerance: float, colour_set: str = "validation colours") -> ErrorReport:
    """The :class:`ErrorReport` of ``lut`` on ``measured`` (:func:`measured_colours`) of ``colour_set``, without a diagnosis."""
    image, reference = measured
    with torch.no_grad():
        errors = code_errors(reference, lut(image.float()))
    return ErrorReport(_quantile(errors), float(errors.max()), image.shape[-1], tolerance, colour_set=colour_set)


def footage_reports(lut, measured: dict, tolerance: float) -> tuple:
    """The :class:`ErrorReport` of ``lut`` on each of ``measured`` (``{colour set: measured_colours(...)}``), not binding."""
    return tuple(replace(measure(lut, colours, tolerance, name), binding=False) for name, colours in measured.items())


def measure_pixels(lut, transform, pixels: torch.Tensor, tolerance: float, colour_set: str = FRAMES) -> ErrorReport:
    """The :class:`ErrorReport` of ``lut`` on every pixel of ``pixels`` (``(..., 3, H, W)``, as the transform receives
    them), :data:`PIXEL_CHUNK` pixels at a time: its p99.9 and max over every channel value.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import bake_lut
        >>> lut = bake_lut(lambda image: image.clamp(0, 1), size=2)
        >>> measure_pixels(lut, lambda image: image.clamp(0, 1), torch.rand(1, 3, 4, 4), 1.0).colours
        16
    """
    flat = sanitize(pixels.detach()).movedim(-3, 0).reshape(3, -1)
    errors, largest = [], 0.0
    with torch.no_grad():
        for chunk in flat.split(PIXEL_CHUNK, dim=1):
            image = chunk.reshape(1, 3, 1, -1)
            chunk_errors = code_errors(transform(image.double()), lut(image.float()))
            largest = max(largest, float(chunk_errors.max()))
            errors.append(chunk_errors.float().flatten())  # the quantile's to float32's 6e-8, at half the memory
    return ErrorReport(_quantile(torch.cat(errors)), largest, flat.shape[1], tolerance, colour_set=colour_set)


def _linear_bounds(lut) -> tuple:
    """A baked LUT's lattice bounds as linear values, two ``(3,)`` float64 tensors."""
    shaper = SHAPERS[lut.shaper]
    return tuple(shaper.decode(v.double().reshape(3, 1), lut.curve, lut.curve_range).flatten()
                 for v in (lut.domain_min, lut.domain_max))


CANDIDATES = (("fitted", 1), (None, 2), (None, 4))
"""Bakes tried for advice, in order: ``(shaper, lattice scale)``; ``None`` keeps the shaper, scale ``k`` means
``k (S-1) + 1`` points, at most :data:`ADVICE_MAX_SIZE`."""

ADVICE_MAX_SIZE = 65
"""Largest lattice the advice bakes (a 129³ bake of a look takes seconds, and would on every warning)."""


def diagnose(report: ErrorReport, lut, transform, measured: tuple, rebake: Callable[[str, int], object],
             scene_colours: int = 0, scene: bool = False) -> ErrorReport:
    """``report`` with its causes and advice; ``rebake(shaper, size)`` bakes the same transform otherwise.

    ``scene_colours``: how many of the measured colours, at their end, are a scene's pixels; ``scene``: whether the bake
    has a scene (measured or not: with ``frames=`` it only shapes the lattice). With a scene the advice
    tries no fitted shaper, the LUT's own included (fitted to the scene, it serves the scene rather than other
    colours, and a new one costs rounds of entry fits), and a fitted shaper's lattice, fitted to the
    scene, is named as a cause with the error on the scene and on the other colours apart.

    The lattice range's share is told by :func:`_within_lattice`; the interpolation's by how the error falls on a finer
    lattice.
    """
    range_error, within_lattice = _within_lattice(lut, transform, measured)
    causes: list[str | None] = []
    if scene_colours and lut.shaper == "fitted":
        causes.append(_scene_fitted_cause(lut, measured, scene_colours))
    causes.append(_range_cause(lut, range_error, report.tolerance))
    finer_size = min(2 * (lut.size - 1) + 1, 256)
    interpolation = measure(lut, within_lattice, report.tolerance).p99_9
    if finer_size > lut.size and interpolation > report.tolerance:
        finer = measure(rebake(lut.shaper, finer_size), within_lattice, report.tolerance)
        ratio = interpolation / max(finer.p99_9, 1e-9)
        kind = "a kink within a cell" if ratio < KINK_RATIO else "size"
        causes.append(f"{kind} (interpolation alone: p99.9 {interpolation:.2f} codes, {ratio:.1f}x less at {finer_size}³)")
    return replace(report, cause="; ".join(c for c in causes if c) or None,
                   advice=_advice(lut, measured, report.tolerance, rebake, advise_fitted=not (scene or scene_colours)))


def _within_lattice(lut, transform, measured: tuple) -> tuple:
    """``(p99.9, measured)``: the transform on ``measured``'s colours clamped per channel to ``lut``'s lattice, its
    p99.9 error in codes against the transform on the colours themselves, and those colours with it as reference."""
    image, reference = measured
    low, high = _linear_bounds(lut)
    with torch.no_grad():
        clamped = torch.maximum(torch.minimum(image, high.reshape(1, 3, 1, 1)), low.reshape(1, 3, 1, 1))
        within_lattice = (image, transform(clamped).double())
    return _quantile(code_errors(reference, within_lattice[1])), within_lattice


def _range_cause(lut, range_error: float, tolerance: float) -> Optional[str]:
    """The lattice range as a cause when its error alone (:func:`_within_lattice`) is above ``tolerance``, else ``None``."""
    if range_error <= tolerance:
        return None
    low, high = _linear_bounds(lut)
    bounds = f"linear {round(float(low.max()), 6) + 0.0:.4g} to {float(high.min()):.4g}"  # LogC's black decodes to -1.6e-10
    return f"lattice range: clamping per channel to the lattice ({bounds}) shifts hues, p99.9 {range_error:.2f} codes by itself"


def worst_case(lut, transform, measured: tuple, tolerance: float) -> ErrorReport:
    """The worst-case :class:`ErrorReport` of ``lut`` on ``measured`` (the validation colours over the whole domain),
    naming the lattice range as its cause when that alone is above ``tolerance``."""
    report = measure(lut, measured, tolerance, WORST_CASE)
    if report.within:
        return report
    return replace(report, cause=_range_cause(lut, _within_lattice(lut, transform, measured)[0], tolerance))


def highlights_report(lut, transform, rebake: Callable[[int], object]) -> Optional[ErrorReport]:
    """The :class:`ErrorReport` of ``lut`` on :func:`~torchgrade.lut.validation.bright_saturated_colours`, when its
    lattice reaches 65504 (``None`` otherwise: a lattice that stops lower clamps highlights by design, and its
    report says where). Above :data:`HIGHLIGHT_TOLERANCE` it names the cause and whether the lattice of twice the
    intervals (``rebake(size)``) holds them.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import bake_lut
        >>> lut = bake_lut(lambda image: image / (1 + image), shaper="logc_extended")
        >>> lut.error_report.highlights.max < 0.5
        True
    """
    if SHAPERS[lut.shaper].linear_range(lut.domain_min, lut.domain_max, lut.curve_range)[1] < HALF_MAX / 2:
        return None
    measured = measured_colours(transform, bright_saturated_colours(), None)
    report = measure(lut, measured, HIGHLIGHT_TOLERANCE, "bright saturated colours")
    if report.max <= HIGHLIGHT_TOLERANCE:
        return report
    size = 2 * (lut.size - 1) + 1
    tried = size <= HIGHLIGHT_ADVICE_MAX_SIZE and lut.shaper != "fitted"  # a fitted lattice would be fitted again: minutes
    finer = measure(rebake(size), measured, HIGHLIGHT_TOLERANCE) if tried else None
    if finer is not None and finer.max <= HIGHLIGHT_TOLERANCE:
        return replace(report, cause=f"the lattice is too coarse there: size={size} holds them (max {finer.max:.2f})")
    still = (f"a lattice twice as fine ({size}³) still misses them by {finer.max:.2f}" if finer
             else f"no lattice twice as fine tried (up to {HIGHLIGHT_ADVICE_MAX_SIZE}³, not fitted)")
    return replace(report, binding=False, cause=f"the transform bends there: {still}; the bake is not judged on them")


def _scene_fitted_cause(lut, measured: tuple, scene_colours: int) -> str:
    """The cause of a scene-fitted lattice: its error on the scene's last ``scene_colours`` measured colours and on the rest."""
    image, reference = measured
    with torch.no_grad():
        errors = code_errors(reference, lut(image.float())).amax(dim=1).flatten()
    scene, others = errors[-scene_colours:], errors[:-scene_colours]
    return (f"lattice fitted to the scene (p99.9 {_quantile(scene):.2f}, max {float(scene.max()):.2f} on its "
            f"{scene_colours} pixels; p99.9 {_quantile(others):.2f}, max {float(others.max()):.2f} on the other colours)")


def _advice(lut, measured: tuple, tolerance: float, rebake, advise_fitted: bool = True) -> str:
    """The first of :data:`CANDIDATES` (a fitted shaper only if ``advise_fitted``) within ``tolerance``, as advice."""
    tried = []
    for shaper, scale in CANDIDATES:
        shaper, size = shaper or lut.shaper, min(scale * (lut.size - 1) + 1, max(ADVICE_MAX_SIZE, lut.size))
        if (shaper, size) in tried or (shaper, size) == (lut.shaper, lut.size) or (shaper == "fitted" and not advise_fitted):
            continue
        tried.append((shaper, size))
        trial = measure(rebake(shaper, size), measured, tolerance)
        if trial.within:
            return f"size={size}, shaper={shaper!r} meets it (p99.9 {trial.p99_9:.2f}, max {trial.max:.2f})"
    if not tried:
        return "no other bake to try: apply the transform directly"
    return f"no bake up to {max(size for _, size in tried)}³ tried meets it: apply the transform directly"


def enforce(report: ErrorReport, strict: bool) -> None:
    """Warn (:class:`LUTAccuracyWarning`) or, with ``strict``, raise ``ValueError`` when ``report`` is over its tolerance."""
    if report.within:
        return
    message = f"the baked LUT misses its transform: {report}"
    if strict:
        raise ValueError(message)
    warnings.warn(message, LUTAccuracyWarning, stacklevel=3)
