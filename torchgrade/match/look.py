"""``match_look``: learn a look from before/after examples, and the :class:`MatchResult` it returns.

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> source = torch.rand(3, 16, 16) * 4
    >>> target = tg.PostFX(grade={"saturation": 30}, tonemap="aces")(source[None])[0]
    >>> result = tg.match_look(source, target, controls=("saturation",), tonemaps=("aces", "neutral"),
    ...                        steps=40, progress=False)
    >>> result.look.to_config()["tonemap"], result.errors["controls"]["p99.9"] < 0.5
    ({'mode': 'aces'}, True)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import torch
from torch import nn

from ..look.postfx import PostFX
from ..lut import LUT3D, bake_lut
from ..tonemap import tone_mapper
from .fit import GRADE_CONTROLS, TONEMAP_CANDIDATES, evaluate, every_loss, fit_controls
from .pixels import PixelPairs, sample_pairs
from .residual import ResidualLUT, fit_residual

__all__ = ["match_look", "MatchResult", "STAGES", "LUT_FILES"]

STAGES = ("grade", "tonemap")
"""The stages a look is matched with; both act per pixel (bloom and exposure depend on the frame)."""

LUT_FILES = (".cube", ".clf")
"""The files :meth:`MatchResult.write_lut` writes, by suffix."""


@dataclass
class MatchResult:
    """What :func:`match_look` found.

    * ``look``: the fitted :class:`~torchgrade.PostFX`; ``look.to_config()`` is the readable recipe.
    * ``residual``: the :class:`~torchgrade.match.ResidualLUT` fitted on top (``residual=True``), else ``None``.
    * ``errors``: ``{"controls": ..., "residual": ...}``, each ``{"p99.9", "max"}`` in 8-bit sRGB codes and
      ``"delta_e_2000"`` (mean), on the held-out pixels (every pixel of the held-out blocks, never fitted).
    * ``history``: the fitting loss at every evaluation (the chosen tone mapper's full fit, then the residual's).
    * ``phases``: ``[(phase, evaluations)]`` in order, how ``history`` divides: ``"global controls"``,
      ``"every control"`` (see :func:`~torchgrade.match.fit.fit_model`), ``"residual Adam"``, ``"residual L-BFGS"``
      (those that ran; ``"fixed"`` for a model with nothing to fit).
    * ``candidates``: each tone mapper screened and its loss after screening (empty when one was given).
    * ``finalists``: each tone mapper fitted fully and its fitted loss, the look's the lowest.
    """

    look: PostFX
    residual: Optional[ResidualLUT]
    errors: dict
    history: list
    candidates: dict
    pixels: PixelPairs = field(repr=False)
    phases: list = field(default_factory=list)
    finalists: dict = field(default_factory=dict)

    def transform(self) -> nn.Module:
        """The per-pixel look as one module: grade, tone mapper, then the residual LUT (if any)."""
        stages = list(self.look.per_pixel_stages()) if self.look.stages() else [nn.Identity()]
        return nn.Sequential(*stages, *([self.residual] if self.residual is not None else []))

    def __call__(self, image: torch.Tensor) -> torch.Tensor:
        return self.transform()(image)

    def bake(self, size="auto", tolerance: float = 1.0, output_encoding: str = "srgb") -> tuple:
        """Bake the whole look (residual included) into a LogC :class:`~torchgrade.LUT3D`; ``(lut, errors on the
        held-out pixels)``. ``size="auto"`` picks the smallest size within ``tolerance`` codes (p99.9) on the fitting
        pixels, whose range the lattice covers. sRGB entries spread the interpolation error evenly over display codes.
        The LUT keeps its bake's :class:`~torchgrade.lut.ErrorReport` (``lut.error_report``)."""
        transform = self.transform()
        with torch.no_grad():
            baked = bake_lut(transform, size=size, shaper="logc", scene=self.pixels.train_source, tolerance=tolerance,
                             output_encoding=output_encoding)
        lut = LUT3D(baked.table.detach(), shaper=baked.shaper, domain=(baked.domain_min, baked.domain_max),
                    output_range=baked.output_range, output_encoding=baked.output_encoding)
        lut.error_report = baked.error_report
        return lut, evaluate(lambda pixels: lut(pixels), self.pixels, display=True)

    def write_lut(self, path, size=65, tolerance: float = 1.0) -> dict:
        """Bake (see :meth:`bake`, with linear entries, as files hold them) and write ``path``, a ``.cube`` or a ``.clf``.

        Returns ``{"size", "p99.9", "max", "delta_e_2000", "report"}``: the held-out errors of the ``.cube`` as read
        back, or of the LUT a CLF states exactly (shaper included, as OpenColorIO applies it), and the bake's
        :class:`~torchgrade.lut.ErrorReport` (validation colours and fitting pixels against the look itself).
        """
        from ..io import read_cube, write_clf, write_cube  # file formats load at their first use, not with torchgrade

        suffix = Path(path).suffix.lower()
        if suffix not in LUT_FILES:
            raise ValueError(f"a look's LUT is written as {' or '.join(LUT_FILES)}, got {path}")
        lut, errors = self.bake(size, tolerance, output_encoding="linear")
        if suffix == ".clf":
            write_clf(path, lut, title="torchgrade match")
        else:
            write_cube(path, lut, title="torchgrade match")
            written = read_cube(path)
            errors = evaluate(lambda pixels: written(pixels), self.pixels, display=True)
        return {"size": lut.size, **errors, "report": lut.error_report}


def _modes(stages, tonemaps) -> tuple:
    unknown = set(stages) - set(STAGES)
    if unknown or not stages:
        raise ValueError(f"stages must be some of {STAGES}, got {tuple(stages)}")
    if "tonemap" not in stages:
        return (None,)
    modes = TONEMAP_CANDIDATES if tonemaps is None else ((tonemaps,) if isinstance(tonemaps, str) else tuple(tonemaps))
    for mode in modes:
        tone_mapper(mode)
    return modes


def _check_counts(**counts) -> None:
    """``ValueError`` naming the first count that is not an integer, at least 0 for steps and 1 for the others.

    Examples:
        >>> _check_counts(steps=0, keep=0)
        Traceback (most recent call last):
        ...
        ValueError: keep must be an integer of at least 1, got 0
    """
    for name, value in counts.items():
        least = 0 if name.endswith("steps") else 1
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise ValueError(f"{name} must be an integer of at least {least}, got {value!r}")


def match_look(source, target, stages=STAGES, mask=None, *, controls=GRADE_CONTROLS, tonemaps=None, aces: bool = False,
               steps: int = 100, screen_steps: int = 20, screen_pixels: int = 2048, keep: int = 3,
               residual: bool = False, residual_size: int = 17, residual_steps: int = 300, smooth: float = 0.05,
               monotone: float = 1.0, max_pixels: int = 16384, residual_pixels: int = 65536, holdout: float = 0.25,
               seed: int = 0, progress: bool = True) -> MatchResult:
    """Fit a look's controls to before/after pairs; see :class:`MatchResult`.

    ``source``: scene-referred linear Rec.709 ``(3, H, W)`` or ``(B, 3, H, W)`` (or a list of them);
    ``target``: the same pictures after the look, display-referred linear [0, 1] when ``"tonemap"`` is in
    ``stages``, else scene-referred; ``mask``: which pixels count (one per pair). A share ``holdout`` of each
    picture's blocks is held out (:func:`~torchgrade.match.pixels.sample_pairs`): the errors are measured on all
    their pixels, and the fit sees none of them. The ``controls`` of the grade (names in
    :class:`~torchgrade.ColorGrade`'s table) are fitted within their documented ranges (a sigmoid onto each range)
    by Levenberg-Marquardt (trials in float64) on ``max_pixels`` pixels stratified by colour, the global controls
    first (:func:`~torchgrade.match.fit.fit_model`), up to ``steps`` trials a phase. ``tonemaps``: a mode, several,
    or ``None`` for :data:`TONEMAP_CANDIDATES` (every SDR mode); with more than one each is fitted for
    ``screen_steps`` trials a phase on ``screen_pixels`` pixels, the ``keep`` best are fitted fully and the lowest
    fitted error chooses (:func:`~torchgrade.match.fit.fit_controls`). ``residual=True`` (display targets) then fits a ``residual_size``³
    :class:`~torchgrade.match.ResidualLUT` with weights ``smooth`` and ``monotone`` on up to ``residual_pixels``.
    ``progress`` shows a tqdm bar per fit with the latest loss (on stderr, when it is a terminal).
    """
    modes = _modes(stages, tonemaps)
    names = tuple(controls) if "grade" in stages else ()
    if residual and modes == (None,):
        raise ValueError("residual=True needs a display-referred target: include 'tonemap' in stages")
    _check_counts(steps=steps, screen_steps=screen_steps, screen_pixels=screen_pixels, keep=keep, max_pixels=max_pixels)
    generator = torch.Generator().manual_seed(seed)
    pixels = sample_pairs(source, target, mask, max(max_pixels, residual_pixels if residual else 0), holdout, generator)
    fitting = PixelPairs(pixels.train_source[:, :, :max_pixels], pixels.train_target[:, :, :max_pixels],
                         pixels.test_source, pixels.test_target)
    fit, candidates, finalists = fit_controls(fitting, names, modes, aces, steps, screen_steps, screen_pixels, keep, progress)
    look = fit.model.look()
    display = modes != (None,)
    errors = {"controls": evaluate(look.per_pixel_stages() if look.stages() else nn.Identity(), pixels, display)}
    phases, fitted_residual = dict(fit.phases), None
    if residual:
        with torch.no_grad():
            shown = look.per_pixel_stages()(pixels.train_source)
        fitted_residual, residual_phases = fit_residual(shown, pixels.train_target, residual_size, residual_steps,
                                                        smooth, monotone, progress)
        phases.update({f"residual {name}": losses for name, losses in residual_phases.items()})
        errors["residual"] = evaluate(nn.Sequential(*look.per_pixel_stages(), fitted_residual), pixels, display)
    history = every_loss(phases)
    counts = [(name, len(losses)) for name, losses in phases.items() if losses]
    return MatchResult(look, fitted_residual, errors, history, candidates, pixels, counts, finalists)
