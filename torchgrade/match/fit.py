"""Fit a look's interpretable controls to before/after pixels, and find its tone mapper.

Every candidate tone mapper is fitted briefly on a small sample; the best few are fitted afresh on every fitting
pixel, and the one whose fitted error is lowest is the look's. Each fit is parsimonious: the global controls first
(exposure, white balance, contrast, hue shift, saturation, with the tone mapper's curve), and only where they do not
reach the target every control. Lift, gamma and gain repeat what exposure and contrast do (a gain is an exposure;
contrast, a power about middle grey in log space, is a gamma's power and a gain), so a fit of all of them at once
lands on any of the equivalent recipes: contrast traded for exposure and gamma.

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> source = torch.rand(3, 16, 16) * 4
    >>> target = tg.PostFX(grade={"contrast": 20}, tonemap="neutral")(source[None])[0]
    >>> result = tg.match_look(source, target, controls=("contrast",), tonemaps="neutral", progress=False)
    >>> round(result.look.to_config()["grade"]["contrast"], 3)
    20.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import torch
from torch import nn

from ..color import linear_to_logc, linear_to_srgb, srgb_to_linear
from ..grading.grade import color_grade
from ..grading.layer import ColorGrade
from ..look.postfx import PostFX
from ..tonemap import HDR_MODES, TONEMAP_MODES, tone_mapper, tonemap
from .bounded import BoundedControls, fittable_names
from .metrics import display_codes, match_errors
from .pixels import PixelPairs
from .solver import levenberg_marquardt

__all__ = ["GRADE_CONTROLS", "GLOBAL_CONTROLS", "TONEMAP_CANDIDATES", "TRACKBALLS", "canonical_trackball",
           "MatchedControls", "every_loss", "pixel_residuals", "fewer_controls_suffice", "fit_model", "ControlsFit",
           "fit_controls", "EVALUATED_PIXELS", "evaluate"]

GRADE_CONTROLS = ("post_exposure", "temperature", "tint", "contrast", "split_shadows", "split_highlights",
                  "split_balance", "lift", "gamma", "gain", "hue_shift", "saturation")
"""The grading controls fitted by default. Colour filter, channel mixer and shadows/midtones/highlights
are left out because, with these, they only add directions that say the same (a gain colour and a colour filter
both scale a channel); pass ``controls=`` to fit them."""

GLOBAL_CONTROLS = ("post_exposure", "temperature", "tint", "contrast", "hue_shift", "saturation")
"""The controls fitted first (those of them a fit is given): one number each, and no two with the same effect."""

TONEMAP_CANDIDATES = tuple(sorted((mode for mode in TONEMAP_MODES if mode != "none" and mode not in HDR_MODES),
                                  key=lambda mode: len(fittable_names(tone_mapper(mode).controls))))
"""The tone mappers tried by default for a display-referred target: every SDR mode of the registry, those with the
fewest curve parameters first (the registry's order among equals). The first that reaches a look ends the search,
so where several do (``filmic``'s eight parameters can draw Narkowicz's ACES fit), the simplest is kept."""

TRACKBALLS = ("lift", "gamma", "gain")

REACHED = 1e-6
"""A fitted loss (mean squared 8-bit codes, or LogC codes ×255) at which the look is reached: a root mean square of a
thousandth of a code, which no other tone mapper could better visibly, so the candidates after it are not fitted. A
fit stops at a hundredth of it, a tenth as far in codes."""

JACOBIAN_DTYPE = torch.float32
"""The dtype the forward differences are computed in (:func:`~torchgrade.match.solver.forward_differences`): the
batch of looks moves half the bytes of float64; the trials, which decide what is kept, are computed in float64."""

# Unity's trackball identity (1, 1, 1, 0) sits on the edge of the range, where a sigmoid has no slope. Any grey
# colour is the same identity (a trackball's colour counts only minus its luminance), so the fit starts at this
# one, in the middle of the sigmoid, and the result is shifted back to Unity's form (see canonical_trackball).
_START = {name: (0.5, 0.5, 0.5, 0.0) for name in TRACKBALLS}


def canonical_trackball(value) -> list:
    """The trackball ``(r, g, b, w)`` with the same effect whose brightest colour channel is 1, as Unity's wheels show it.

    A trackball's colour acts as its sRGB decoding minus its luminance, so adding one amount to every decoded
    channel changes nothing; this adds the amount that brings the largest to 1.

    Examples:
        >>> canonical_trackball([0.5, 0.5, 0.5, 0.1])
        [1.0, 1.0, 1.0, 0.1]
    """
    decoded = srgb_to_linear(torch.as_tensor(value[:3], dtype=torch.float64))
    shifted = linear_to_srgb(decoded + (1.0 - decoded.max()))
    return [round(float(v), 5) for v in shifted] + [value[3]]


class MatchedControls(nn.Module):
    """A grade (the controls ``names``, in range) followed by tone mapper ``mode`` (its curve parameters fitted), or no tone mapper.

    Its parameters may be given per sample (``torch.func.functional_call`` with ``(B, ...)`` values and ``B``
    pictures): the stages take per-sample controls, which is how :func:`fit_stages` nudges every control at once.
    """

    def __init__(self, names, mode: Optional[str], aces: bool = False):
        super().__init__()
        self.aces, self.mode = aces, mode
        self.grade = BoundedControls(ColorGrade.controls, names, _START)
        curve_table = tone_mapper(mode).controls if mode else {}
        self.curve = BoundedControls(curve_table, fittable_names(curve_table))

    def forward(self, pixels: torch.Tensor) -> torch.Tensor:
        graded = color_grade(pixels, aces=self.aces, **self.grade.values()) if self.grade.raw else pixels
        return tonemap(graded, self.mode, **self.curve.values()) if self.mode else graded

    def parameter_names(self, controls) -> list:
        """The names of the parameters behind the grading ``controls`` (those this model fits) and the curve's.

        Examples:
            >>> MatchedControls(("contrast", "lift"), "hable").parameter_names(("contrast",))
            ['grade.raw.contrast', 'curve.raw.exposure_bias', 'curve.raw.white_point']
        """
        return [f"grade.raw.{name}" for name in self.grade.raw if name in controls] + [f"curve.raw.{name}" for name in self.curve.raw]

    def look(self) -> PostFX:
        """The fitted look as a :class:`~torchgrade.PostFX` of rounded plain values (what ``to_config`` shows)."""
        grade = {"aces": self.aces, **self.grade.plain_values()}
        grade.update({name: canonical_trackball(grade[name]) for name in TRACKBALLS if name in grade})
        return PostFX(grade=grade, tonemap={"mode": self.mode, **self.curve.plain_values()} if self.mode else None)


def every_loss(phases: dict) -> list:
    """The losses of ``{phase: [losses]}`` as one list, in the phases' order.

    Examples:
        >>> every_loss({"screening": [4.0, 2.0], "Levenberg-Marquardt": [1.0]})
        [4.0, 2.0, 1.0]
    """
    return [loss for losses in phases.values() for loss in losses]


def pixel_residuals(display: bool):
    """The encoding whose differences a fit of controls minimises the mean square of: 8-bit sRGB codes (display
    targets) or LogC codes ×255 (scene-referred targets)."""
    return display_codes if display else (lambda x: 255.0 * linear_to_logc(x.clamp_min(0.0)))


def fewer_controls_suffice(loss_fewer: float, fewer: int, loss_more: float, more: int, residuals: int) -> bool:
    """Whether a fit of ``fewer`` parameters explains ``residuals`` values as well as one of ``more``, by Akaike's
    information criterion for least squares, ``n ln(mean square) + 2k`` (Akaike, *A new look at the statistical
    model identification*, 1974): the extra parameters must lower the mean square by more than ``e^(2Δk/n)``.
    A target that is a look of the global controls, saved as 8-bit codes, is fitted by them to its rounding; lift,
    gamma and gain then fit only the rounding, by about ``Δk / n`` of it, and are left out.

    Examples:
        >>> fewer_controls_suffice(0.08335, 6, 0.0833, 25, 49152)   # 0.06 % lower for 19 more: the fewer
        True
        >>> fewer_controls_suffice(0.5, 6, 0.0833, 25, 49152)
        False
    """
    tiny = 1e-300
    return residuals * math.log(max(loss_fewer, tiny)) + 2 * fewer <= residuals * math.log(max(loss_more, tiny)) + 2 * more


def _fit_parameters(model: MatchedControls, names: list, source: torch.Tensor, wanted: torch.Tensor, encode,
                    iterations: int, progress: bool, desc: str) -> list:
    """Fit the parameters ``names`` of ``model`` (the others held) so that ``encode(model(source))`` meets ``wanted``,
    by :func:`~torchgrade.match.solver.levenberg_marquardt`; the loss at every evaluation."""
    parameters = dict(model.named_parameters())
    shapes = [parameters[name].shape for name in names]
    sizes = [math.prod(shape) for shape in shapes]
    fixed = {name: parameter.detach() for name, parameter in parameters.items() if name not in names}

    def residuals(theta: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
        pieces = theta.to(dtype).split(sizes, dim=1)
        values = {name: value.to(dtype) for name, value in fixed.items()}
        values.update({name: piece.reshape(len(theta), *shape) for name, piece, shape in zip(names, pieces, shapes)})
        pixels = source.to(dtype).expand(len(theta), -1, -1, -1)
        shown = torch.func.functional_call(model, values, (pixels,))
        return encode(shown).reshape(len(theta), -1) - wanted.to(dtype)

    start = torch.cat([parameters[name].detach().reshape(-1) for name in names])
    theta, losses = levenberg_marquardt(residuals, start, iterations, progress, desc, JACOBIAN_DTYPE, REACHED / 100)
    with torch.no_grad():
        for name, piece in zip(names, theta.split(sizes)):
            parameters[name].copy_(piece.reshape(parameters[name].shape))
    return losses


def fit_model(model: MatchedControls, source: torch.Tensor, target: torch.Tensor, display: bool, iterations: int,
              progress: bool, desc: str) -> tuple:
    """Fit ``model`` to the pixels ``(1, 3, N, 1)``, up to ``iterations`` trials a phase; ``(losses by phase, loss)``.

    Parsimonious: the global controls among the model's (:data:`GLOBAL_CONTROLS`) with the curve first, from the
    identity (``"global controls"``); where they do not reach the target (:data:`REACHED`), every control from the
    identity (``"every control"``), and the recipe with fewer controls is kept where it explains the pixels as well
    (:func:`fewer_controls_suffice`). Every control from the identity rather than from the global controls' fit,
    which stands in for what lift, gamma and gain do with exposure and contrast and can leave the full fit in a
    valley it does not leave. A model with nothing to fit gives ``({"fixed": [its loss]}, its loss)``.

    Examples:
        >>> import torch
        >>> source = torch.rand(1, 3, 64, 1, dtype=torch.float64) * 4
        >>> target = MatchedControls(("contrast",), "aces").double()
        >>> with torch.no_grad():
        ...     _ = target.grade.raw["contrast"].fill_(0.3)
        ...     shown = target(source)
        >>> model = MatchedControls(("contrast", "gamma"), "aces").double()
        >>> phases, loss = fit_model(model, source, shown, True, 20, False, "fit")
        >>> list(phases), loss < 1e-8, round(model.grade.raw["contrast"].item(), 4)
        (['global controls'], True, 0.3)
    """
    encode = pixel_residuals(display)
    wanted = encode(target).reshape(-1)
    names = list(model.grade.raw)
    first = [name for name in names if name in GLOBAL_CONTROLS]
    every = model.parameter_names(names)
    if not every:
        with torch.no_grad():
            loss = float((encode(model(source)).reshape(-1) - wanted).square().mean())
        return {"fixed": [loss]}, loss
    phases = {}
    if first and len(first) < len(names):
        identity = {name: value.clone() for name, value in model.state_dict().items()}
        fewer = model.parameter_names(first)
        phases["global controls"] = _fit_parameters(model, fewer, source, wanted, encode, iterations, progress, desc)
        if _last(phases["global controls"]) <= REACHED:
            return phases, _last(phases["global controls"])
        globals_only = {name: value.clone() for name, value in model.state_dict().items()}
        model.load_state_dict(identity)
    phases["every control"] = _fit_parameters(model, every, source, wanted, encode, iterations, progress, desc)
    loss = _last(phases["every control"])
    if "global controls" in phases:
        count = dict(model.named_parameters())
        sizes = [sum(count[name].numel() for name in group) for group in (fewer, every)]
        if fewer_controls_suffice(_last(phases["global controls"]), sizes[0], loss, sizes[1], wanted.numel()):
            model.load_state_dict(globals_only)
            loss = _last(phases["global controls"])
    return phases, loss


def _last(losses: list) -> float:
    """The latest loss, ``inf`` where it is not finite (a fit that failed is never chosen)."""
    return losses[-1] if math.isfinite(losses[-1]) else float("inf")


@dataclass
class ControlsFit:
    """One candidate's fitted controls, its losses by phase (see :func:`fit_model`) and its fitted loss."""

    model: MatchedControls
    phases: dict = field(default_factory=dict)
    loss: float = float("inf")


def fit_controls(pairs: PixelPairs, names, modes, aces: bool, steps: int, screen_steps: int, screen_pixels: int,
                 keep: int, progress: bool) -> tuple:
    """Fit the controls ``names`` with each tone mapper of ``modes``; ``(the best fit, {mode: loss after screening},
    {mode: loss after the full fit})``.

    Each fit is :func:`fit_model`'s. With several modes, each is fitted for up to ``screen_steps`` trials a phase on
    the first ``screen_pixels`` fitting pixels (a stratified sample too: they are in random order), in order, until
    one reaches :data:`REACHED`; the ``keep`` lowest are then fitted afresh, in that order, for up to ``steps`` trials
    a phase on every fitting pixel, until one reaches it; the lowest fitted loss is the look's.
    """
    display = modes != (None,)
    source, target = pairs.train_source, pairs.train_target
    finalists, screened = modes, {}
    if len(modes) > 1:
        small = source[:, :, :screen_pixels], target[:, :, :screen_pixels]
        for mode in modes:
            model = MatchedControls(names, mode, aces).to(source)
            screened[mode] = fit_model(model, *small, display, screen_steps, progress, f"screen {mode}")[1]
            if screened[mode] <= REACHED:
                break  # no other tone mapper could show the look visibly better
        finalists = sorted(screened, key=lambda mode: screened[mode])[:keep]
    fits = []
    for mode in finalists:
        fit = ControlsFit(MatchedControls(names, mode, aces).to(source))
        fit.phases, fit.loss = fit_model(fit.model, source, target, display, steps, progress, f"match {mode or 'scene-referred'}")
        fits.append(fit)
        if fit.loss <= REACHED:
            break
    best = min(fits, key=lambda fit: fit.loss)
    return best, screened, {fit.model.mode: fit.loss for fit in fits}


EVALUATED_PIXELS = 1 << 16
"""Held-out pixels a look is applied to at a time: its working memory, not the picture's, bounds the evaluation."""


def evaluate(transform, pairs: PixelPairs, display: bool) -> dict:
    """:func:`~torchgrade.match.metrics.match_errors` on the held-out pixels (scene-referred ones viewed through ``neutral``)."""
    with torch.no_grad():
        fitted = torch.cat([transform(part) for part in pairs.test_source.split(EVALUATED_PIXELS, dim=2)], dim=2)
        target = pairs.test_target
        if not display:
            fitted, target = tonemap(fitted, "neutral"), tonemap(target, "neutral")
    return match_errors(target.reshape(3, -1), fitted.reshape(3, -1))
