"""Baking: evaluate any per-pixel transform on a LUT's lattice, pick its size, and report its error.

**Display-referred LUTs** (baked from a transform containing a display-referred stage, a tone
mapper: :attr:`~torchgrade.base.stage.Stage.display_referred`) record ``output_range = (0, 1)``: the clip
happens *after* the lookup. A transform that ends with its tone mapper is baked with that tone
mapper's ``clip`` off, so the table holds a smooth curve and the clip is exact instead of
interpolated. Kinks inside the transform (the tone mapper's ``max(0, ·)`` of its graded input, on
surfaces oblique to the lattice) stay in the table and are what limits a 33³ LUT's accuracy on
strong looks.

Examples:
    >>> import torch
    >>> lut = bake_lut(lambda image: image * 0.5, size=3)
    >>> lut(torch.full((1, 3, 1, 1), 0.5)).flatten().tolist()
    [0.25, 0.25, 0.25]
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import replace
from typing import Callable, Optional

import torch
from torch import nn
from tqdm import tqdm

from ..base.images import HALF_MAX, check_image, check_on_cpu, sanitize
from ..base.params import check_choice
from .entries import ENTRY_CHOICES, SCENE_WEIGHT, fit_entries, scene_pixels
from .fit import SCENE_FIT_WEIGHT, SCENE_MIN_SIZE, fit_scene_shaper, fit_shaper, refine_shaper
from .lattice import MIN_SIZE, check_size, checked_domain, lattice
from .layer import LUT3D
from .apply import OUTPUT_ENCODINGS, encode_output
from .footage import footage_colours
from .report import (REALISTIC, code_errors, diagnose, enforce, footage_reports, highlights_report, measure, measure_pixels,
                     measured_colours, worst_case)
from .shapers import DEFAULT_DOMAINS, DEFAULT_SIZES, SHAPERS
from .validation import realistic_colours, validation_colours

__all__ = ["AUTO_SIZES", "LOOK_SHAPER", "bake_lut", "bake_look", "live_stages", "expects_hdr", "is_display_referred",
           "scene_domain", "srgb_code_error"]

AUTO_SIZES = (3, 5, 9, 17, 33, 65, 129, 256)
"""Sizes tried first by ``bake_lut(size="auto")`` before bisecting between the last two."""

LOOK_SHAPER = "logc_extended"
"""The lattice ``shaper="auto"`` bakes a look on (:func:`bake_look`): a look takes scene-referred light, up to 65504,
whether or not it tone maps."""


def _modules(transform) -> list:
    return list(transform.modules()) if isinstance(transform, nn.Module) else []


def is_display_referred(transform) -> bool:
    """Whether ``transform``'s output is display-referred: it is or contains a stage flagged so (a tone mapper).

    Examples:
        >>> is_display_referred(lambda image: image)
        False
    """
    return any(getattr(m, "display_referred", False) for m in _modules(transform))


def expects_hdr(transform) -> bool:
    """The rule behind ``shaper="auto"``: does ``transform`` take scene-referred (HDR) input?

    An explicit ``transform.expects_hdr`` attribute wins; otherwise a transform containing a module
    whose ``expects_hdr`` is true (a tone mapper with a curve) is HDR. Everything else (a grade
    alone, a plain function) is treated as taking [0, 1] input.

    Examples:
        >>> expects_hdr(lambda image: image)
        False
    """
    declared = getattr(transform, "expects_hdr", None)
    if declared is not None:
        return bool(declared)
    return any(getattr(m, "expects_hdr", False) for m in _modules(transform))


def bake_lut(transform: Callable[[torch.Tensor], torch.Tensor], size=None, shaper: str = "auto",
             scene: Optional[torch.Tensor] = None, tolerance: float = 0.5, chunk: int = 1 << 21,
             output_encoding: str = "linear", progress: bool = False, domain: Optional[tuple] = None,
             report_tolerance: float = 1.0, strict: bool = False, entries: str = "sampled",
             frames: Optional[torch.Tensor] = None) -> LUT3D:
    """Bake a per-pixel ``transform`` on ``(N, 3, H, W)`` tensors, or a look, into a :class:`~torchgrade.LUT3D`.

    A look (:class:`~torchgrade.PostFX`) is baked by :func:`bake_look`, as ``look.to_lut()`` and ``torchgrade bake``
    bake it: the same table from the same arguments. It must hold nothing a LUT cannot (exposure, bloom, a look LUT,
    dither, a display: ``look.to_lut()`` keeps those live around the LUT).

    The transform is evaluated once on the lattice, in float64 and in shaper space, and the float64
    table kept (lattice point ``u`` is fed ``shaper.decode(min + u (max - min))``), ``chunk`` points at
    a time. The table stays connected to the transform's parameters, so a LUT can be fitted by
    gradient descent.

    * ``shaper``: ``"linear"``, ``"logc"`` (black to linear 58.86), ``"logc_extended"`` (the ``"logc"`` lattice, then
      12 more intervals even in stops to 65504: :class:`~torchgrade.lut.shapers.LogCExtendedShaper`), ``"logc_hdr"``
      (the former default: LogC to 58.86 on 27 intervals, a tail on 5), ``"fitted"`` or ``"auto"``
      (``"logc_extended"`` when :func:`expects_hdr`); the choice is stored as ``lut.shaper`` and shown in ``repr(lut)``.
      ``"fitted"`` fits a per-channel shaper from black to 65504 (its lattice domain is [0, 1]): to the
      transform's bends (:func:`~torchgrade.lut.fit_shaper`), or, given a ``scene``, to where tables with
      fitted entries miss the scene's pixels (:func:`~torchgrade.lut.fit.fit_scene_shaper`: a few bake-and-fit
      rounds, tens of seconds at 33³). A scene-fitted 33³ table with fitted entries misses the scene by less than
      any 33³ LogC table can on the strong look, but serves colours far from the scene's worse than the default
      (benchmarks/results/lut_fit.md); its report says by how much.
    * ``scene``: an image the LUT is for. The lattice domain then follows its dynamic range: the
      top is the scene's largest value (after the non-finite policy), the bottom stays at black.
    * ``frames``: frames the LUT will grade, ``(..., 3, H, W)`` as the transform receives them. The report's p99.9
      and max are then measured on every one of their pixels instead of the realistic colours, and it says so (its
      diagnosis, when over the tolerance, on at most :data:`~torchgrade.lut.report.SCENE_PIXELS` of them, evenly
      strided); nothing else changes. The realistic colours stand for natural footage, and the report's ``footage``
      figures for charts and warm practicals (:mod:`~torchgrade.lut.footage`); a LUT for known footage is best
      judged on it.
    * ``domain``: ``(min, max)`` of the lattice in shaper code values (numbers or RGB triples, as
      :class:`~torchgrade.LUT3D` takes them), overriding the shaper's default and the scene's range
      (a ``scene`` then only serves ``size="auto"``).
    * ``size``: 2..256 (by default the shaper's :data:`~torchgrade.lut.shapers.DEFAULT_SIZES`), or ``"auto"`` with a ``scene``: the smallest size whose error on the scene is
      at most ``tolerance`` 8-bit sRGB code values at the 99.9th percentile (:func:`srgb_code_error`,
      against direct float64 evaluation). Sizes :data:`AUTO_SIZES` are tried in order, then the gap
      below the first that passes is bisected (error is assumed to fall as the size grows); if none
      passes, 256 is returned.
    * ``output_encoding``: how the table stores outputs (:data:`~torchgrade.lut.OUTPUT_ENCODINGS`).
      ``"srgb"`` spreads the interpolation error evenly over display code values, which suits
      display-referred LUTs (benchmarks/results/lut.md lists the gain on real images).
    * A display-referred transform (see the module docstring) gives a LUT that clamps to [0, 1]
      after the lookup, baked with the final tone mapper's clip off.
    * ``progress``: show a progress bar (tqdm, on stderr, when it is a terminal) while the lattice
      is evaluated; a 256³ bake of a grade and tone mapper takes seconds.
    * ``entries``: ``"sampled"`` (the transform at the lattice points) or ``"fitted"``: then refined by
      :func:`~torchgrade.lut.fit_entries` for tetrahedral lookup on other validation colours and the
      scene's pixels, for the smallest largest error (detached from the transform's parameters; seconds
      at 33³). On the strong look and a lattice fitted to the scene it cuts the max error on the scene 7-24x, to
      1.59 / 0.26 / 0.51 codes on Desk / CandleGlass / GoldenGate (benchmarks/results/lut_fit.md).
      A scene pixel weighs :data:`~torchgrade.lut.SCENE_WEIGHT` in the fit, or
      :data:`~torchgrade.lut.fit.SCENE_FIT_WEIGHT` on a scene-fitted lattice.
    * The LUT's error on realistic colours (:func:`~torchgrade.lut.realistic_colours`, plus the scene's
      pixels), or on the ``frames``, is measured and kept as ``lut.error_report`` (:class:`~torchgrade.lut.ErrorReport`),
      with (for an HDR bake without ``frames``) the same on colour charts and warm practicals as its ``footage``, the
      worst case, on the validation colours over the whole domain, as its ``worst_case``, and for a lattice that
      reaches 65504 its max error on bright saturated colours as its ``highlights``
      (:func:`~torchgrade.lut.report.highlights_report`). Above ``report_tolerance`` 8-bit codes at p99.9 on the
      realistic colours, or with highlights off by more than :data:`~torchgrade.lut.report.HIGHLIGHT_TOLERANCE`,
      the report names the cause and a bake that meets it, and the bake warns
      (:class:`~torchgrade.lut.LUTAccuracyWarning`), or raises ``ValueError`` with ``strict=True``.

    Examples:
        >>> bake_lut(lambda image: image, size=5, shaper="logc").shaper
        'logc'
    """
    check_on_cpu(transform, "bake_lut")
    if is_look(transform):
        live = live_stages(transform)
        if live:
            raise ValueError(f"bake_lut(look) bakes a look's grade, primary grade and tone mapping; this look also runs "
                             f"{', '.join(live)}, which a LUT cannot hold: look.to_lut() keeps them live around the LUT, "
                             "bake_lut(look.per_pixel_stages()) bakes the rest alone")
        transform, shaper, scene, frames = _per_pixel(transform, shaper, scene, frames)
    if shaper == "auto":
        shaper = "logc_extended" if expects_hdr(transform) else "linear"
    check_choice("bake shaper", shaper, DEFAULT_DOMAINS)
    size = DEFAULT_SIZES[shaper] if size is None else size
    check_choice("output encoding", output_encoding, OUTPUT_ENCODINGS)
    check_choice("entries", entries, ENTRY_CHOICES)
    if size == "auto" and scene is None:
        raise ValueError('bake_lut(size="auto") needs scene=image to measure the error on')
    if size == "auto" and scene is not None and shaper == "fitted":
        raise ValueError('bake_lut(size="auto") with shaper="fitted" and a scene would fit a lattice to the scene at '
                         "every size it tries (rounds of entry fits each): give a size")
    if domain is not None and shaper == "fitted":
        raise ValueError("a fitted shaper's lattice domain is [0, 1] (its curve places the planes); domain= is for "
                         "the other shapers")
    if size == "auto" and not tolerance > 0:
        raise ValueError(f'bake_lut(size="auto") needs a tolerance above 0 (8-bit codes), got {tolerance}')
    if size != "auto":
        size = check_size(size)  # before the transform runs on anything, as the domain
        if shaper == "fitted" and scene is not None and size < SCENE_MIN_SIZE:
            raise ValueError(f"a lattice fitted to a scene needs size >= {SCENE_MIN_SIZE}, got {size}")
    if domain is not None:
        domain = checked_domain(domain)
    hdr = shaper != "linear" or expects_hdr(transform)
    if frames is not None:
        check_image(frames, "frames")
    measured, scene_colours = _headline_colours(transform, hdr, scene, frames)
    worst = measured_colours(transform, validation_colours(hdr), None)
    bake = _baker(transform, domain, scene, chunk, output_encoding, progress, worst, hdr)
    if size == "auto" and scene is not None:  # "auto" without a scene was refused above
        lut = _smallest_within(lambda n: bake(shaper, n), transform, scene, tolerance)
    else:
        lut = bake(shaper, size)
    if entries == "fitted":
        lut = fit_entries(lut, transform, scene, hdr, scene_weight=_scene_weight(lut, scene))
    if frames is None:
        report = measure(lut, measured, report_tolerance, REALISTIC if scene is None else f"{REALISTIC} and scene pixels")
    else:
        report = measure_pixels(lut, transform, frames, report_tolerance)
    if not report.within:
        report = diagnose(report, lut, transform, measured, _rebaker(bake, lut), scene_colours, scene is not None)
    footage = {} if frames is not None or not hdr else footage_colours()
    report = replace(report, worst_case=worst_case(lut, transform, worst, report_tolerance),
                     highlights=highlights_report(lut, transform, lambda n: bake(lut.shaper, n)),
                     footage=footage_reports(lut, {name: measured_colours(transform, colours, None)
                                                   for name, colours in footage.items()}, report_tolerance))
    enforce(report, strict)
    lut.error_report = report
    return lut


def bake_look(look, size=None, shaper: str = "auto", scene=None, frames=None, **bake) -> LUT3D:
    """The LUT of ``look``'s per-pixel stages (``look.per_pixel_stages()``: grade, primary grade, tone mapping), the one
    bake behind ``bake_lut(look)``, ``look.to_lut()`` and ``torchgrade bake``; the look's other stages are left out.

    ``shaper="auto"`` is :data:`LOOK_SHAPER` (a look takes scene-referred light, tone mapped or not); ``scene`` and
    ``frames`` are frames the look takes, each measured as the LUT receives it (``look.per_pixel_input``: after the
    exposure and bloom); ``frames`` may also be a list of frames of different sizes. The other arguments are
    :func:`bake_lut`'s.

    Examples:
        >>> import torchgrade as tg
        >>> look = tg.PostFX(bloom={"intensity": 0.5}, grade={"contrast": 10}, tonemap="aces")
        >>> lut = bake_look(look, size=5, report_tolerance=float("inf"))
        >>> lut.shaper, lut.size, live_stages(look)
        ('logc_extended', 5, ['bloom'])
    """
    transform, shaper, scene, frames = _per_pixel(look, shaper, scene, frames)
    return bake_lut(transform, size=size, shaper=shaper, scene=scene, frames=frames, **bake)


def is_look(transform) -> bool:
    """Whether ``transform`` is a look (it has per-pixel stages a LUT holds and frames them, as :class:`~torchgrade.PostFX`).

    Examples:
        >>> is_look(lambda image: image)
        False
    """
    return callable(getattr(transform, "per_pixel_stages", None)) and callable(getattr(transform, "per_pixel_input", None))


def live_stages(look) -> list:
    """The names of ``look``'s stages that a LUT of it leaves out (run live): all but its per-pixel stages."""
    baked = list(look.per_pixel_stages())
    return [name for name, stage in look.stages().items() if all(stage is not module for module in baked)]


def _per_pixel(look, shaper: str, scene, frames) -> tuple:
    """``(transform, shaper, scene, frames)`` that bake ``look``: its per-pixel stages, ``"auto"`` as
    :data:`LOOK_SHAPER`, the scene and frames as those stages receive them (``(1, 3, 1, N)`` for frames)."""
    transform = look.per_pixel_stages()
    with torch.no_grad():
        if scene is not None:
            check_image(scene, "scene")
            scene = look.per_pixel_input(scene.reshape(-1, *scene.shape[-3:]))
        if frames is not None:
            frames = [frames] if isinstance(frames, torch.Tensor) else list(frames)
            for frame in frames:
                check_image(frame, "frames")
            received = [look.per_pixel_input(f.reshape(-1, *f.shape[-3:])).movedim(-3, 0).reshape(3, -1) for f in frames]
            frames = torch.cat(received, dim=-1).reshape(1, 3, 1, -1)
    return transform, LOOK_SHAPER if shaper == "auto" else shaper, scene, frames


def _baker(transform, domain, scene, chunk: int, output_encoding: str, progress: bool, measured: tuple, hdr: bool) -> Callable:
    """``bake(shaper, size, curve=None, curve_range=(0, 1)) -> LUT3D`` for ``transform``: the lattice domain, fitted
    curve and clip handling of :func:`bake_lut`. Bakes without a curve are kept and returned again.

    A fitted shaper is fitted once per size: to the scene's pixels when there is a scene
    (:func:`~torchgrade.lut.fit.fit_scene_shaper`), else to the transform and the ``measured`` colours
    (:func:`~torchgrade.lut.report.measured_colours` of the validation colours: the whole domain).
    """
    display = is_display_referred(transform)
    image, reference = measured
    fitted, baked = {}, {}

    def cached(shaper: str, size: int, curve=None, curve_range=(0.0, 1.0)) -> LUT3D:
        if curve is not None:
            return bake(shaper, size, curve, curve_range)
        if (shaper, size) not in baked:
            baked[shaper, size] = bake(shaper, size)
        return baked[shaper, size]

    def fit_to_look(shaper: str, size: int) -> tuple:
        with _final_clip_off(transform) if display else contextlib.nullcontext():
            start, curve_range = fit_shaper(transform, hdr=hdr)
        with torch.no_grad():
            return refine_shaper(start, curve_range, lambda c: bake(shaper, size, c, curve_range), image[0, :, 0],
                                 lambda lut: code_errors(reference, lut(image.float())).amax(dim=1).flatten()), curve_range

    def fit_to_scene(shaper: str, size: int) -> tuple:
        pixels = scene_pixels(scene)
        with torch.no_grad():
            direct = transform(pixels.reshape(1, 3, 1, -1)).double()
        return fit_scene_shaper(
            lambda c, r: fit_entries(bake(shaper, size, c, r), transform, scene, hdr, scene_weight=SCENE_FIT_WEIGHT),
            pixels, lambda lut: code_errors(direct, lut(pixels.reshape(1, 3, 1, -1).float())).amax(dim=1).flatten(),
            size, hdr, progress=progress)

    def bake(shaper: str, size: int, curve=None, curve_range=(0.0, 1.0)) -> LUT3D:
        if SHAPERS[shaper].takes_curve and curve is None:
            if size not in fitted:
                fitted[size] = (fit_to_look if scene is None else fit_to_scene)(shaper, size)
            curve, curve_range = fitted[size]
        with _final_clip_off(transform) if display else contextlib.nullcontext():
            lattice_domain = domain
            if lattice_domain is None:
                lattice_domain = DEFAULT_DOMAINS[shaper] if scene is None or curve is not None else scene_domain(scene, shaper)
            lattice_domain = checked_domain(lattice_domain)  # the lattice is baked where the lookup will find it
            values = _evaluate_on_lattice(transform, size, shaper, lattice_domain, chunk, progress, curve, curve_range)
        # Bounded as every table is (the non-finite policy's ±65504): a grade clamps there, and a matrix after it can
        # reach a few hundredths beyond.
        return LUT3D(encode_output(values.clamp(-HALF_MAX, HALF_MAX), output_encoding), shaper=shaper, domain=lattice_domain,
                     output_range=(0.0, 1.0) if display else None, output_encoding=output_encoding,
                     curve=curve, curve_range=curve_range)

    return cached


def _headline_colours(transform, hdr: bool, scene: Optional[torch.Tensor], frames: Optional[torch.Tensor]) -> tuple:
    """``(measured, scene colours)``: the realistic colours and the scene's pixels (the last ``scene colours`` of them),
    or at most :data:`~torchgrade.lut.report.SCENE_PIXELS` of the frames' pixels (the diagnosis's: the report itself
    measures every pixel), with the transform on them (:func:`~torchgrade.lut.report.measured_colours`)."""
    realistic = realistic_colours(hdr)
    if frames is not None:
        return measured_colours(transform, realistic[:, :0], frames), 0
    measured = measured_colours(transform, realistic, scene)
    return measured, measured[0].shape[-1] - realistic.shape[1]


def _scene_weight(lut: LUT3D, scene: Optional[torch.Tensor]) -> float:
    """Weight of a scene pixel when ``lut``'s entries are fitted: :data:`~torchgrade.lut.fit.SCENE_FIT_WEIGHT` on a
    scene-fitted lattice, else :data:`~torchgrade.lut.SCENE_WEIGHT`."""
    return SCENE_FIT_WEIGHT if scene is not None and lut.shaper == "fitted" else SCENE_WEIGHT


def _rebaker(bake: Callable, lut: LUT3D) -> Callable:
    """``rebake(shaper, size)`` for the error report's causes and advice: ``lut``'s own fitted curve at other sizes
    (its plane density carries over), instead of a new fit per size."""
    def rebake(shaper: str, size: int) -> LUT3D:
        if shaper == lut.shaper and lut.curve is not None:
            return bake(shaper, size, lut.curve.double(), lut.curve_range)
        return bake(shaper, size)

    return rebake


@contextlib.contextmanager
def _final_clip_off(transform):
    """Within the block, the display-referred stage that produces ``transform``'s output runs with ``clip=False``.

    That stage is ``transform`` itself or the last module of nested ``nn.Sequential`` containers;
    any other transform is left as it is. Only valid when the LUT clamps to [0, 1] after the lookup.
    """
    final = transform
    while isinstance(final, nn.Sequential) and len(final):
        final = final[-1]
    if not getattr(final, "display_referred", False) or not getattr(final, "clip", False):
        yield
        return
    final.clip = False
    try:
        yield
    finally:
        final.clip = True


def scene_domain(scene: torch.Tensor, shaper: str) -> tuple:
    """Lattice domain ``(black, shaper(max(scene)))`` in shaper code values, for :func:`bake_lut`.

    Examples:
        >>> import torch
        >>> scene_domain(torch.full((1, 3, 2, 2), 4.0), "linear")
        (0.0, 4.0)
    """
    check_image(scene, "scene")
    top = sanitize(scene.detach().double()).max().clamp_min(1e-3)
    return DEFAULT_DOMAINS[shaper][0], float(SHAPERS[shaper].encode(top))


def _evaluate_on_lattice(transform, size: int, shaper: str, domain, chunk: int, progress: bool = False,
                         curve: Optional[torch.Tensor] = None, curve_range=(0.0, 1.0)) -> torch.Tensor:
    """Evaluate ``transform`` at every lattice point, float64; returns the ``(S, S, S, 3)`` table.

    ``progress`` shows a bar over the blue slices of the lattice (on a terminal only).
    """
    low, high = (torch.as_tensor(v, dtype=torch.float64) for v in domain)
    codes = (low + lattice(size) * (high - low)).reshape(-1, 3).t()
    inputs = SHAPERS[shaper].decode(codes, curve, curve_range).t().reshape(size, size, size, 3)  # (b, g, r, 3)
    slices_per_chunk = max(1, chunk // (size * size))
    outputs = []
    with tqdm(total=size, desc=f"baking {size}³", unit="slice", disable=None if progress else True, leave=False) as bar:
        for block in inputs.split(slices_per_chunk, dim=0):
            image = block.reshape(1, -1, size, 3).permute(0, 3, 1, 2)  # H = b·S + g, W = r
            result = transform(image)
            check_image(result, "transform output")
            outputs.append(result.double().permute(0, 2, 3, 1).reshape(-1, size, size, 3))
            bar.update(block.shape[0])
    return torch.cat(outputs, dim=0)


def srgb_code_error(reference: torch.Tensor, approximation: torch.Tensor, quantile: float = 0.999) -> float:
    """Absolute error in 8-bit sRGB code values, ``255 |srgb(clamp(a, 0, 1)) - srgb(clamp(b, 0, 1))|``, at ``quantile``.

    Examples:
        >>> import torch
        >>> srgb_code_error(torch.ones(4), torch.ones(4))
        0.0
    """
    error = code_errors(reference, approximation).flatten()
    rank = max(1, math.ceil(quantile * error.numel()))
    return float(error.kthvalue(rank).values)


def _smallest_within(bake: Callable[[int], LUT3D], transform, scene: torch.Tensor, tolerance: float) -> LUT3D:
    """The LUT of the smallest size whose :func:`srgb_code_error` on ``scene`` is within ``tolerance``."""
    with torch.no_grad():
        reference = transform(sanitize(scene.double()))

    def passes(lut: LUT3D) -> bool:
        with torch.no_grad():
            return srgb_code_error(reference, lut(scene.double())) <= tolerance

    smaller = MIN_SIZE - 1
    for candidate in AUTO_SIZES:
        lut = bake(candidate)
        if passes(lut):
            break
        smaller = candidate
    else:
        return lut
    while candidate - smaller > 1:
        middle = (candidate + smaller) // 2
        trial = bake(middle)
        if passes(trial):
            candidate, lut = middle, trial
        else:
            smaller = middle
    return lut
