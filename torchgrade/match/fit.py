"""Fit a look's interpretable controls (and optionally a residual LUT) to before/after pairs.

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> source = torch.rand(3, 16, 16) * 4
    >>> target = tg.PostFX(grade={"contrast": 20}, tonemap="neutral")(source[None])[0]
    >>> result = tg.match_look(source, target, controls=("contrast",), tonemaps="neutral", steps=60, progress=False)
    >>> round(result.look.to_config()["grade"]["contrast"])
    20
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import torch
from torch import nn
from tqdm import tqdm

from ..color import linear_to_logc, linear_to_srgb, srgb_to_linear
from ..grading.grade import color_grade
from ..grading.layer import ColorGrade
from ..look.postfx import PostFX
from ..lut.kernels import KERNELS
from ..lut.lattice import planar_table
from ..tonemap import tone_mapper, tonemap
from .bounded import BoundedControls, fittable_names
from .metrics import display_codes, match_errors
from .pixels import PixelPairs
from .residual import ResidualLUT, lattice_coordinates, monotonicity, smoothness

__all__ = ["GRADE_CONTROLS", "TONEMAP_CANDIDATES", "TRACKBALLS", "canonical_trackball", "MatchedControls", "optimise",
           "levenberg_marquardt", "every_loss", "pixel_residuals", "ControlsFit", "fit_controls",
           "fit_residual", "evaluate"]

GRADE_CONTROLS = ("post_exposure", "temperature", "tint", "contrast", "split_shadows", "split_highlights",
                  "split_balance", "lift", "gamma", "gain", "hue_shift", "saturation")
"""The grading controls fitted by default: the global ones. Colour filter, channel mixer and shadows/midtones/highlights
are left out because, with these, they only add directions that say the same (a gain colour and a colour filter
both scale a channel); pass ``controls=`` to fit them."""

TONEMAP_CANDIDATES = ("neutral", "aces", "aces_reference", "aces_hill", "aces_narkowicz", "reinhard",
                      "reinhard_extended", "reinhard_luminance", "hable", "agx", "agx_godot", "khronos_pbr_neutral")
"""The tone mappers tried by default for a display-referred target (SDR modes whose curves differ; ``filmic`` and
``unreal_filmic`` add many parameters that say the same, and are tried only when named)."""


TRACKBALLS = ("lift", "gamma", "gain")

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
    """A grade (the controls ``names``, in range) followed by tone mapper ``mode`` (its curve parameters fitted), or no tone mapper."""

    def __init__(self, names, mode: Optional[str], aces: bool = False):
        super().__init__()
        self.aces, self.mode = aces, mode
        self.grade = BoundedControls(ColorGrade.controls, names, _START)
        curve_table = tone_mapper(mode).controls if mode else {}
        self.curve = BoundedControls(curve_table, fittable_names(curve_table))

    def forward(self, pixels: torch.Tensor) -> torch.Tensor:
        graded = color_grade(pixels, aces=self.aces, **self.grade.values()) if self.grade.raw else pixels
        return tonemap(graded, self.mode, **self.curve.values()) if self.mode else graded

    def look(self) -> PostFX:
        """The fitted look as a :class:`~torchgrade.PostFX` of rounded plain values (what ``to_config`` shows)."""
        grade = {"aces": self.aces, **self.grade.plain_values()}
        grade.update({name: canonical_trackball(grade[name]) for name in TRACKBALLS if name in grade})
        return PostFX(grade=grade, tonemap={"mode": self.mode, **self.curve.plain_values()} if self.mode else None)


def optimise(module: nn.Module, loss_fn, steps: int, lbfgs_steps: int, lr: float, progress: bool, desc: str) -> dict:
    """Adam for ``steps``, then up to ``lbfgs_steps`` L-BFGS iterations (strong Wolfe line search).

    Returns the loss at every evaluation, in order, by optimiser: ``{"Adam": [one per step], "L-BFGS": [...]}``
    (L-BFGS evaluates a few times per iteration; no ``"L-BFGS"`` without iterations); a module with nothing to fit
    gives ``{"fixed": [its loss]}``.
    ``progress`` shows a tqdm bar (on stderr, when it is a terminal) with the latest loss.
    """
    parameters = [p for p in module.parameters() if p.requires_grad]
    if not parameters:
        with torch.no_grad():
            return {"fixed": [float(loss_fn())]}
    history = []
    with tqdm(total=steps + lbfgs_steps, desc=desc, disable=None if progress else True, leave=False) as bar:

        def closure():
            optimiser.zero_grad()
            loss = loss_fn()
            loss.backward()
            history.append(loss.item())
            bar.set_postfix(loss=f"{history[-1]:.4g}", refresh=False)
            return loss

        optimiser: torch.optim.Optimizer = torch.optim.Adam(parameters, lr=lr)
        for _ in range(steps):
            optimiser.step(closure)
            bar.update()
        if lbfgs_steps:
            # One call runs every iteration: L-BFGS's curvature pairs are only kept within a call.
            optimiser = torch.optim.LBFGS(parameters, lr=1.0, max_iter=lbfgs_steps, history_size=20,
                                          tolerance_grad=1e-12, tolerance_change=1e-14, line_search_fn="strong_wolfe")
            optimiser.step(closure)
            bar.update(lbfgs_steps)
    return {"Adam": history[:steps], **({"L-BFGS": history[steps:]} if lbfgs_steps else {})}


def levenberg_marquardt(module: nn.Module, residuals, iterations: int, progress: bool, desc: str) -> list:
    """Up to ``iterations`` Levenberg-Marquardt trials on ``module``'s trainable parameters, minimising the mean of
    ``residuals(parameters)²`` (``parameters``: ``{name: tensor}`` for :func:`torch.func.functional_call`); the loss
    at every evaluation.

    Each trial solves ``(JᵀJ + μ D) h = -Jᵀr`` with the residuals' Jacobian ``J`` (forward-mode, one pass per
    parameter: :func:`torch.func.jacfwd`) and ``D`` the largest diagonal of ``JᵀJ`` met so far (Moré's scaling, so a
    control that stops mattering, as split balance does when both split-toning colours turn grey, keeps its damping);
    a step that lowers the loss is taken and ``μ`` shrinks by ``max(1/3, 1 - (2ρ - 1)³)``, ``ρ`` the actual over the
    predicted decrease, otherwise ``μ`` grows by ``ν`` (2, doubling while refused): Madsen, Nielsen & Tingleff,
    *Methods for non-linear least squares problems* (2004), §3.2; Moré, *The Levenberg-Marquardt algorithm:
    implementation and theory* (1978). It stops when a taken step lowers the loss by less than 1e-12 of it, or a step
    would move the parameters by less than 1e-12 of their norm.
    On a target the controls can reach exactly, the steps become Gauss-Newton's and converge quadratically, where
    first-order methods crawl along the directions in which controls say nearly the same.

    Examples:
        >>> import torch
        >>> line = torch.nn.Linear(1, 1, dtype=torch.float64)
        >>> x = torch.tensor([[0.0], [1.0], [2.0]], dtype=torch.float64)
        >>> losses = levenberg_marquardt(line, lambda p: torch.func.functional_call(line, p, (x,)).flatten()
        ...                              - torch.tensor([1.0, 3.0, 5.0], dtype=torch.float64), 10, False, "line")
        >>> round(line.weight.item(), 6), round(line.bias.item(), 6), losses[-1] < 1e-20
        (2.0, 1.0, True)
    """
    names = [name for name, parameter in module.named_parameters() if parameter.requires_grad]
    parameters = [module.get_parameter(name) for name in names]
    sizes = [parameter.numel() for parameter in parameters]

    def residuals_at(theta: torch.Tensor) -> torch.Tensor:
        pieces = theta.split(sizes)
        return residuals({name: piece.view_as(p) for name, piece, p in zip(names, pieces, parameters)})

    with torch.no_grad():
        theta = torch.cat([parameter.detach().flatten() for parameter in parameters])
        r = residuals_at(theta)
    loss = float(r.square().mean())
    history = [loss]
    damping, growth, jacobian_due = 1e-3, 2.0, True
    scale = torch.zeros_like(theta)  # the largest diagonal of JᵀJ met so far (none is negative)
    with tqdm(total=iterations, desc=desc, disable=None if progress else True, leave=False) as bar:
        for _ in range(iterations):
            if jacobian_due:
                jacobian = torch.func.jacfwd(residuals_at)(theta)
                gradient, curvature = jacobian.T @ r, jacobian.T @ jacobian
                scale = torch.maximum(scale, curvature.diagonal())
                scale = scale.clamp_min(1e-12 * float(scale.max()) + 1e-300)
                jacobian_due = False
            with torch.no_grad():
                step = torch.linalg.solve(curvature + torch.diag(damping * scale), -gradient)
                if float(step.norm()) <= 1e-12 * (float(theta.norm()) + 1e-12):
                    break  # the parameters no longer move: converged, or the loss is down to rounding
                trial = residuals_at(theta + step)
            bar.update()
            trial_loss = float(trial.square().mean())
            history.append(trial_loss)
            bar.set_postfix(loss=f"{trial_loss:.4g}", refresh=False)
            predicted = float(step @ (damping * scale * step - gradient)) / r.numel()
            if math.isfinite(trial_loss) and trial_loss < loss and predicted > 0:
                ratio, decrease = (loss - trial_loss) / predicted, loss - trial_loss
                theta, r, loss, jacobian_due = theta + step, trial, trial_loss, True
                damping, growth = damping * max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3), 2.0
                if decrease <= 1e-12 * (loss + decrease):
                    break
            else:
                damping, growth = damping * growth, growth * 2.0
                if not math.isfinite(damping * growth):
                    break
    with torch.no_grad():
        for parameter, piece in zip(parameters, theta.split(sizes)):
            parameter.copy_(piece.view_as(parameter))
    return history


def every_loss(phases: dict) -> list:
    """The losses of ``{phase: [losses]}`` as one list, in the phases' order.

    Examples:
        >>> every_loss({"Adam": [4.0, 2.0], "L-BFGS": [1.0]})
        [4.0, 2.0, 1.0]
    """
    return [loss for losses in phases.values() for loss in losses]


def pixel_residuals(display: bool):
    """The differences a fit of controls minimises the mean square of: in 8-bit sRGB codes (display targets) or in
    LogC codes ×255 (scene-referred targets), flattened.

    The residual LUT's fit uses Huber instead (squared within one code, linear beyond), so pixels no smooth
    correction can reach (several sources shown as one clipped display colour, each with its own target) do
    not bend it elsewhere.
    """
    encode = display_codes if display else (lambda x: 255.0 * linear_to_logc(x.clamp_min(0.0)))
    return lambda fitted, target: (encode(fitted) - encode(target)).flatten()


@dataclass
class ControlsFit:
    """One candidate's fitted controls, its losses by phase (``{"screening": [...], "Adam": [...], ...}``) and final fitting loss."""

    model: MatchedControls
    phases: dict = field(default_factory=dict)
    loss: float = float("inf")


def fit_controls(pairs: PixelPairs, names, modes, aces: bool, steps: int, lm_steps: int, screen_steps: int,
                 lr: float, progress: bool, max_pixels: int) -> tuple:
    """Screen every tone mapper in ``modes`` with ``screen_steps`` Adam steps, finish the best with ``steps`` more and
    up to ``lm_steps`` Levenberg-Marquardt trials (:func:`levenberg_marquardt`); ``(fit, {mode: loss})``.

    Fits on the first ``max_pixels`` fitting pixels (they are shuffled).
    """
    residuals_of = pixel_residuals(display=modes != (None,))
    source, target = pairs.train_source[:, :, :max_pixels], pairs.train_target[:, :, :max_pixels]

    def loss_fn(model):
        return lambda: residuals_of(model(source), target).square().mean()

    fits = {mode: ControlsFit(MatchedControls(names, mode, aces).to(source.device)) for mode in modes}
    if len(modes) > 1:
        for mode, fit in fits.items():
            screening = every_loss(optimise(fit.model, loss_fn(fit.model), screen_steps, 0, lr, progress, f"screen {mode}"))
            fit.phases["screening"] = screening
            fit.loss = float("inf") if math.isnan(screening[-1]) else screening[-1]
    best = min(fits.values(), key=lambda f: f.loss)
    target_kind = best.model.mode or "scene-referred"
    best.phases.update(optimise(best.model, loss_fn(best.model), steps, 0, lr, progress, f"match {target_kind}"))
    if lm_steps and "fixed" not in best.phases:
        best.phases["Levenberg-Marquardt"] = levenberg_marquardt(
            best.model, lambda values: residuals_of(torch.func.functional_call(best.model, values, (source,)), target),
            lm_steps, progress, f"refine {target_kind}")
    if len(modes) == 1:
        best.loss = every_loss(best.phases)[-1]
    return best, {mode: fit.loss for mode, fit in fits.items()}


def fit_residual(display: torch.Tensor, target: torch.Tensor, size: int, steps: int, smooth: float, monotone: float,
                 progress: bool) -> tuple:
    """Fit a :class:`ResidualLUT` from the look's display output to the target; ``(residual, losses by optimiser)``.

    The data term is Huber in 8-bit codes (see :func:`pixel_residuals`); the table is looked up at the pixels'
    :func:`~torchgrade.match.residual.lattice_coordinates`, computed once.
    """
    residual = ResidualLUT(size).to(display.device)
    coords = lattice_coordinates(display, size)
    target_codes = display_codes(target).movedim(-3, 0).reshape(3, -1).T
    scale = 255.0**2  # regularisers on the table's [0, 1] units, brought to the data term's squared codes

    def loss_fn():
        table = residual.lut.table
        # Entries are sRGB codes: decoding, clamping to the display and encoding again is a clamp.
        codes = 255.0 * KERNELS["tetrahedral"](coords, planar_table(table), size).T.clamp(0.0, 1.0)
        data = 2.0 * nn.functional.smooth_l1_loss(codes, target_codes, beta=1.0)
        return data + scale * (smooth * smoothness(table) + monotone * monotonicity(table))

    history = optimise(residual, loss_fn, steps // 2, steps - steps // 2, 2e-3, progress, f"residual {size}³")
    return residual, history


def evaluate(transform, pairs: PixelPairs, display: bool) -> dict:
    """:func:`~torchgrade.match.metrics.match_errors` on the held-out pixels (scene-referred ones viewed through ``neutral``)."""
    with torch.no_grad():
        fitted, target = transform(pairs.test_source), pairs.test_target
        if not display:
            fitted, target = tonemap(fitted, "neutral"), tonemap(target, "neutral")
    return match_errors(target.reshape(3, -1), fitted.reshape(3, -1))
