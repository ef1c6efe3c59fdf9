"""Grading curves: monotone cubic Hermite splines through control points, differentiable.

A curve is given by control points ``((x0, y0), (x1, y1), ...)`` with strictly increasing ``x``
(a sequence, or an ``(N, 2)`` tensor; an ``nn.Parameter`` makes the ``y`` values learnable). The
spline is Fritsch and Carlson's monotone piecewise cubic Hermite interpolant (SIAM J. Numer. Anal.
17(2), 1980): between two control points it never overshoots them, so it is monotone wherever
the points are and never leaves the range of the ``y`` values. Tangents:

1. secants ``d_k = (y_{k+1} - y_k) / (x_{k+1} - x_k)``;
2. ``m_k = (d_{k-1} + d_k) / 2`` where both secants have the same strict sign, else 0 (a flat
   stretch or a local extremum); the end points of an open curve take their secant;
3. interval by interval, in order: when ``m_k² + m_{k+1}² > 9 d_k²`` both tangents are scaled by
   ``τ = 3 |d_k| / sqrt(m_k² + m_{k+1}²)``.

Open curves are clamped outside ``[x0, x_last]`` (constant ends, as a clamped texture lookup);
periodic curves (hue, in turns) wrap, the last point joining the first one turn later.
The result is differentiable with respect to the evaluated values and the ``y`` of the control
points; the ``x`` positions are fixed (their gradient is not computed).
"""

from __future__ import annotations

import torch


def curve_points(points, like: torch.Tensor, name: str = "curve") -> tuple:
    """Control points as ``(x, y)`` 1-D tensors in ``like``'s dtype and device (``x`` detached).

    Raises ``ValueError`` naming ``name`` unless there are at least two points, shaped ``(N, 2)``,
    with strictly increasing ``x``.
    """
    if isinstance(points, torch.Tensor):
        table = points.to(device=like.device, dtype=like.dtype)
    else:
        try:
            table = torch.as_tensor(points, dtype=like.dtype, device=like.device)
        except (TypeError, ValueError, RuntimeError) as error:
            raise ValueError(f"{name} must be a sequence of (x, y) points: {error}") from None
    if table.dim() != 2 or table.shape[1] != 2 or table.shape[0] < 2:
        raise ValueError(f"{name} must be at least two (x, y) points, shape (N, 2), got shape {tuple(table.shape)}")
    x, y = table.unbind(1)
    x = x.detach()
    if not bool((x[1:] > x[:-1]).all()):
        raise ValueError(f"{name} x values must be strictly increasing, got {x.tolist()}")
    return x, y


def monotone_tangents(x: torch.Tensor, y: torch.Tensor, periodic: bool = False) -> torch.Tensor:
    """Fritsch–Carlson tangents at the control points (steps 1-3 of the module docstring).

    For a periodic curve ``x`` must lie within one turn; the last interval runs from the last point
    to the first one a turn later.
    """
    if periodic:
        x, y = torch.cat((x, x[:1] + 1.0)), torch.cat((y, y[:1]))
    secants = (y[1:] - y[:-1]) / (x[1:] - x[:-1])
    before = torch.cat((secants[-1:] if periodic else secants[:1], secants))
    after = torch.cat((secants, secants[:1] if periodic else secants[-1:]))
    tangents = torch.where(before * after > 0, (before + after) / 2, torch.zeros_like(before))
    tangents = list(tangents[:-1] if periodic else tangents)
    count = len(tangents)
    for k in range(len(secants)):
        low, high = tangents[k], tangents[(k + 1) % count]
        norm_sq = low * low + high * high
        limit_sq = 9.0 * secants[k] * secants[k]
        too_steep = norm_sq > limit_sq
        tau = torch.sqrt(torch.where(too_steep, limit_sq / torch.where(too_steep, norm_sq, torch.ones_like(norm_sq)), torch.ones_like(norm_sq)))
        tangents[k], tangents[(k + 1) % count] = low * tau, high * tau
    return torch.stack(tangents)


def hermite(x: torch.Tensor, y: torch.Tensor, tangents: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Piecewise cubic Hermite interpolation through ``(x, y)`` with ``tangents``, at ``t`` in ``[x0, x_last]``.

    With ``s = (t - x_k) / h`` on interval ``k`` of width ``h``:
    ``(2s³ - 3s² + 1) y_k + (s³ - 2s² + s) h m_k + (3s² - 2s³) y_{k+1} + (s³ - s²) h m_{k+1}``.
    """
    interval = torch.zeros_like(t, dtype=torch.long)
    for knot in x[1:-1]:
        interval = interval + (t >= knot).long()

    def at(values: torch.Tensor) -> torch.Tensor:
        return values.index_select(0, interval.reshape(-1)).reshape(interval.shape)

    x0, width = at(x[:-1]), at(x[1:] - x[:-1])
    s = (t - x0) / width
    s2, s3 = s * s, s * s * s
    return (
        (2 * s3 - 3 * s2 + 1) * at(y[:-1])
        + (s3 - 2 * s2 + s) * width * at(tangents[:-1])
        + (3 * s2 - 2 * s3) * at(y[1:])
        + (s3 - s2) * width * at(tangents[1:])
    )


def evaluate_curve(points, t: torch.Tensor, periodic: bool = False, name: str = "curve") -> torch.Tensor:
    """The monotone spline through ``points`` at ``t``: clamped ends, or wrapped to one turn if ``periodic``."""
    x, y = curve_points(points, t, name)
    if periodic and x[-1] >= x[0] + 1.0:
        raise ValueError(f"{name} is periodic: its x values must lie within one turn, got {x.tolist()}")
    tangents = monotone_tangents(x, y, periodic)
    if periodic:
        x, y, tangents = torch.cat((x, x[:1] + 1.0)), torch.cat((y, y[:1])), torch.cat((tangents, tangents[:1]))
        return hermite(x, y, tangents, x[0] + torch.remainder(t - x[0], 1.0))
    return hermite(x, y, tangents, t.clamp(x[0].item(), x[-1].item()))
