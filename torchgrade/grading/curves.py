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

import math
from dataclasses import dataclass
from typing import Any, Optional

import torch

from ..base.params import check_range
from ..runtime import constant
from ..base.controls import Control

__all__ = [
    "CurveControl",
    "curve_points",
    "monotone_tangents",
    "hermite",
    "evaluate_curve",
    "curve_is_identity",
    "check_curve",
    "stored_curve",
    "MAX_CURVE_POINTS",
]

MAX_CURVE_POINTS = 256
"""Most control points a curve takes: a drawn grading curve has a handful; the bound keeps an untrusted
config from building a million-point spline that every pixel then searches."""


@dataclass(frozen=True)
class CurveControl(Control):
    """A curve control of a stage's table: control points, ``None`` (identity) by default.

    ``periodic``: the curve wraps in hue (turns) instead of being clamped at its ends. ``flat``: the
    ``y`` of a flat curve that changes nothing (``None``: the diagonal from (0, 0) to (1, 1) does).
    Curves have a variable number of points, so they are never ONNX graph inputs.

    Examples:
        >>> hue_vs_sat = CurveControl(periodic=True, flat=0.5)
        >>> hue_vs_sat.kind, hue_vs_sat.default
        ('value', None)
    """

    default: Any = None
    periodic: bool = False
    flat: Optional[float] = None


def curve_points(points, like: torch.Tensor, name: str = "curve") -> tuple:
    """Control points as ``(x, y)`` 1-D tensors in ``like``'s dtype and device (``x`` detached).

    Raises ``ValueError`` naming ``name`` unless there are at least two points, shaped ``(N, 2)``, with strictly
    increasing ``x`` for points given as numbers (a tensor's are not read here: a stage checks them when they are set,
    :func:`check_curve`).

    Examples:
        >>> x, y = curve_points(((0.0, 0.25), (1.0, 0.75)), torch.empty(()))
        >>> x.tolist(), y.tolist()
        ([0.0, 1.0], [0.25, 0.75])
    """
    if isinstance(points, torch.Tensor):
        table = points.to(device=like.device, dtype=like.dtype)
    else:  # checked in Python and made once on the device (runtime.constant): nothing is read back or copied per call
        table = constant(_plain_points(points, name), like)
    if table.dim() != 2 or table.shape[1] != 2 or table.shape[0] < 2:
        raise ValueError(f"{name} must be at least two (x, y) points, shape (N, 2), got shape {tuple(table.shape)}")
    x, y = table.unbind(1)
    return x.detach(), y


def _spans_a_turn(points) -> bool:
    """Whether a periodic curve's ``x`` values, given as numbers, span a turn or more (a tensor's are checked when a
    stage's curve is set, :func:`check_curve`)."""
    return not isinstance(points, torch.Tensor) and float(points[-1][0]) >= float(points[0][0]) + 1.0


def _plain_points(points, name: str) -> tuple:
    """Points given as numbers, as a tuple of ``(x, y)`` float pairs, checked: at least two, finite, ``x`` strictly increasing."""
    try:
        pairs = tuple((float(x), float(y)) for x, y in points)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a sequence of (x, y) points: {error}") from None
    if len(pairs) < 2:
        raise ValueError(f"{name} must be at least two (x, y) points, shape (N, 2), got shape ({len(pairs)}, 2)")
    if not all(math.isfinite(v) for pair in pairs for v in pair):  # NaN passes every comparison below
        raise ValueError(f"{name} must be finite (x, y) points, got {list(pairs)}")
    if any(later[0] <= earlier[0] for earlier, later in zip(pairs, pairs[1:])):
        raise ValueError(f"{name} x values must be strictly increasing, got {[x for x, _ in pairs]}")
    return pairs


def monotone_tangents(x: torch.Tensor, y: torch.Tensor, periodic: bool = False) -> torch.Tensor:
    """Fritsch–Carlson tangents at the control points (steps 1-3 of the module docstring).

    For a periodic curve ``x`` must lie within one turn; the last interval runs from the last point
    to the first one a turn later.

    Examples:
        >>> monotone_tangents(torch.tensor([0.0, 0.5, 1.0]), torch.tensor([0.0, 0.5, 1.0])).tolist()
        [1.0, 1.0, 1.0]
    """
    if periodic:
        x, y = torch.cat((x, x[:1] + 1.0)), torch.cat((y, y[:1]))
    secants = (y[1:] - y[:-1]) / (x[1:] - x[:-1])
    before = torch.cat((secants[-1:] if periodic else secants[:1], secants))
    after = torch.cat((secants, secants[:1] if periodic else secants[-1:]))
    mean = torch.where(before * after > 0, (before + after) / 2, torch.zeros_like(before))
    tangents = list(mean[:-1] if periodic else mean)
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

    Examples:
        >>> x, y = torch.tensor([0.0, 1.0]), torch.tensor([0.0, 1.0])
        >>> hermite(x, y, torch.ones(2), torch.tensor([0.25])).tolist()
        [0.25]
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
    """The monotone spline through ``points`` at ``t``: clamped ends, or wrapped to one turn if ``periodic``.

    Examples:
        >>> evaluate_curve(((0.0, 0.0), (0.5, 0.8), (1.0, 1.0)), torch.tensor([0.5, 2.0])).tolist()
        [0.800000011920929, 1.0]
    """
    x, y = curve_points(points, t, name)
    if periodic and _spans_a_turn(points):
        raise ValueError(f"{name} is periodic: its x values must lie within one turn, got {x.tolist()}")
    tangents = monotone_tangents(x, y, periodic)
    if periodic:
        x, y, tangents = torch.cat((x, x[:1] + 1.0)), torch.cat((y, y[:1])), torch.cat((tangents, tangents[:1]))
        return hermite(x, y, tangents, x[0] + torch.remainder(t - x[0], 1.0))
    return hermite(x, y, tangents, t.clamp(x[0], x[-1]))  # tensor bounds: no value read back


def curve_is_identity(points, flat: Optional[float]) -> bool:
    """True for a curve that changes nothing: None, no points, all ``y == flat``, or (``flat`` None) the diagonal.

    Points given as numbers are compared in Python; a curve given as a tensor (learnable or not) is never identity:
    deciding would read its values back from the device at every call, or from a compiler's graph input.

    Examples:
        >>> curve_is_identity(((0.0, 0.5), (0.5, 0.5)), flat=0.5), curve_is_identity(((0.0, 0.0), (1.0, 1.0)), None)
        (True, True)
        >>> curve_is_identity(((0.0, 0.2), (1.0, 1.0)), None)
        False
    """
    if points is None:
        return True
    if isinstance(points, torch.Tensor):
        return False
    pairs = [(float(x), float(y)) for x, y in points]
    if not pairs:
        return True
    if flat is not None:
        return all(y == flat for _, y in pairs)
    return pairs[0][0] == 0.0 and pairs[-1][0] == 1.0 and all(y == x for x, y in pairs)


def check_curve(name: str, points, periodic: bool = False) -> None:
    """Raise ``ValueError`` naming curve ``name`` unless its points are valid: ``x`` strictly increasing in
    [0, 1] (periodic curves: [0, 1)), ``y`` in [0, 1], at most :data:`MAX_CURVE_POINTS` points. None and
    no points are valid (identity).

    Examples:
        >>> check_curve("hue_vs_hue", ((0.0, 0.5), (1.0, 0.5)), periodic=True)
        Traceback (most recent call last):
        ...
        ValueError: hue_vs_hue x values must lie in [0, 1), got [0.0, 1.0]
    """
    if points is None:
        return
    if not isinstance(points, (torch.Tensor, list, tuple)):
        raise ValueError(f"{name} must be a sequence of (x, y) points or None, got {type(points).__name__}")
    if len(points) > MAX_CURVE_POINTS:
        raise ValueError(f"{name} has {len(points)} points; a curve takes at most {MAX_CURVE_POINTS}")
    if len(points) == 0:
        return
    x, y = curve_points(points, torch.empty((), dtype=torch.float64), name)
    if not bool((x[1:] > x[:-1]).all()):
        raise ValueError(f"{name} x values must be strictly increasing, got {x.tolist()}")
    if x[0] < 0.0 or x[-1] > 1.0 or (periodic and x[-1] >= 1.0):
        raise ValueError(f"{name} x values must lie in [0, 1{')' if periodic else ']'}, got {x.tolist()}")
    check_range(y, f"{name} y", 0.0, 1.0)


def stored_curve(points):
    """A curve as a stage keeps it: a tensor as given, a sequence as a tuple of (x, y) float pairs.

    Examples:
        >>> stored_curve([[0, 0.5], [1, 0.5]])
        ((0.0, 0.5), (1.0, 0.5))
    """
    if points is None or isinstance(points, torch.Tensor):
        return points
    return tuple((float(x), float(y)) for x, y in points)
