"""Levenberg-Marquardt on pixel residuals, with a Jacobian of forward differences computed as one batch.

A look's controls are per-sample parameters (a ``(B,)`` contrast grades each picture of a batch with its own), so the
``P`` looks a forward-difference Jacobian needs (each control nudged in turn) run as one batch of ``P + 1`` looks on
the same pixels: one pass of the grade's few hundred elementwise operations, where :func:`torch.func.jacfwd` makes
``P`` forward-mode passes through them (``benchmarks/results/match.md`` compares the two).

Examples:
    >>> import torch
    >>> x = torch.tensor([0.0, 1.0, 2.0], dtype=torch.float64)
    >>> line = lambda theta, dtype: theta[:, :1] * x + theta[:, 1:] - torch.tensor([1.0, 3.0, 5.0], dtype=torch.float64)
    >>> theta, losses = levenberg_marquardt(line, torch.zeros(2, dtype=torch.float64), 10, False, "line")
    >>> [round(v, 6) for v in theta.tolist()], losses[-1] < 1e-20
    ([2.0, 1.0], True)
"""

from __future__ import annotations

import math

import torch
from tqdm import tqdm

__all__ = ["forward_differences", "levenberg_marquardt"]

STALL_STEPS = 10
"""Steps taken over which a fit that no longer progresses is stopped (see :data:`STALL`)."""

STALL = 1e-3
"""A fit whose loss fell by less than this share over its last :data:`STALL_STEPS` steps stops: it crawls along
directions in which its controls say nearly the same, a thousandth of its error at a time, which no viewer sees."""


def forward_differences(residuals, theta: torch.Tensor, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """The Jacobian ``(M, P)`` at ``theta`` (``(P,)``) of ``residuals``, which takes a batch ``(B, P)`` and a dtype to
    ``(B, M)`` computed in that dtype: ``(r(θ + h_j e_j) - r(θ)) / h_j`` for every ``j``, in one batch of ``P + 1``.

    ``h = √ε · (1 + |θ|)``, ``ε`` the dtype's: the step that balances the truncation error (``h``) against the
    rounding error (``ε / h``), as MINPACK's ``lmdif`` takes it (Moré, Garbow and Hillstrom, 1980). In float32 the
    Jacobian is good to about 1e-3 relative, enough to steer Levenberg-Marquardt, whose trials are measured in float64.

    Examples:
        >>> square = lambda theta, dtype: theta.to(dtype) ** 2
        >>> [round(v, 5) for v in forward_differences(square, torch.tensor([3.0], dtype=torch.float64)).flatten().tolist()]
        [6.0]
    """
    steps = torch.finfo(dtype).eps ** 0.5 * (1.0 + theta.abs())
    batch = torch.cat([theta[None], theta + torch.diag(steps)])
    values = residuals(batch, dtype).double()
    return ((values[1:] - values[0]) / steps[:, None]).T


def levenberg_marquardt(residuals, theta: torch.Tensor, iterations: int, progress: bool, desc: str,
                        jacobian_dtype: torch.dtype = torch.float64, floor: float = 0.0) -> tuple:
    """Up to ``iterations`` Levenberg-Marquardt trials from ``theta`` (``(P,)``, float64) minimising the mean of
    ``residuals(θ)²``, ``residuals`` taking a batch ``(B, P)`` and a dtype to ``(B, M)`` computed in that dtype (the
    trials in float64, the Jacobian in ``jacobian_dtype``); ``(θ, the loss at every evaluation)``.

    Each trial solves ``(JᵀJ + μ D) h = -Jᵀr`` with the Jacobian ``J`` of :func:`forward_differences` and ``D`` the
    largest diagonal of ``JᵀJ`` met so far (Moré's scaling, so a control that stops mattering, as split balance does
    when both split-toning colours turn grey, keeps its damping); a step that lowers the loss is taken and ``μ``
    shrinks by ``max(1/3, 1 - (2ρ - 1)³)``, ``ρ`` the actual over the predicted decrease, otherwise ``μ`` grows by
    ``ν`` (2, doubling while refused): Madsen, Nielsen & Tingleff, *Methods for non-linear least squares problems*
    (2004), §3.2; Moré, *The Levenberg-Marquardt algorithm: implementation and theory* (1978). It stops when a taken
    step lowers the loss by less than 1e-12 of it, or a step would move the parameters by less than 1e-12 of their
    norm, or (:data:`STALL`) when its last :data:`STALL_STEPS` steps lowered it by less than a thousandth, or when
    the loss is down to ``floor``.
    On a target the controls can reach exactly, the steps become Gauss-Newton's and converge quadratically,
    where first-order methods crawl along the directions in which controls say nearly the same.
    ``progress`` shows a tqdm bar (on stderr, when it is a terminal) with the latest loss.
    """
    with torch.no_grad():
        r = residuals(theta[None], torch.float64)[0]
    loss = float(r.square().mean())
    history, taken = [loss], [loss]
    damping, growth, jacobian_due = 1e-3, 2.0, True
    scale = torch.zeros_like(theta)  # the largest diagonal of JᵀJ met so far (none is negative)
    with tqdm(total=iterations, desc=desc, disable=None if progress else True, leave=False) as bar, torch.no_grad():
        for _ in range(iterations):
            if not math.isfinite(loss) or loss <= floor:
                break
            if jacobian_due:
                jacobian = forward_differences(residuals, theta, jacobian_dtype)
                gradient, curvature = jacobian.T @ r, jacobian.T @ jacobian
                scale = torch.maximum(scale, curvature.diagonal())
                scale = scale.clamp_min(1e-12 * float(scale.max()) + 1e-300)
                jacobian_due = False
            step = torch.linalg.solve(curvature + torch.diag(damping * scale), -gradient)
            if float(step.norm()) <= 1e-12 * (float(theta.norm()) + 1e-12):
                break  # the parameters no longer move: converged, or the loss is down to rounding
            trial = residuals((theta + step)[None], torch.float64)[0]
            bar.update()
            trial_loss = float(trial.square().mean())
            history.append(trial_loss)
            bar.set_postfix(loss=f"{trial_loss:.4g}", refresh=False)
            predicted = float(step @ (damping * scale * step - gradient)) / r.numel()
            if math.isfinite(trial_loss) and trial_loss < loss and predicted > 0:
                ratio, decrease = (loss - trial_loss) / predicted, loss - trial_loss
                theta, r, loss, jacobian_due = theta + step, trial, trial_loss, True
                damping, growth = damping * max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3), 2.0
                taken.append(loss)
                stalled = len(taken) > STALL_STEPS and loss >= (1.0 - STALL) * taken[-1 - STALL_STEPS]
                if decrease <= 1e-12 * (loss + decrease) or stalled:
                    break
            else:
                damping, growth = damping * growth, growth * 2.0
                if not math.isfinite(damping * growth):
                    break

    return theta, history
