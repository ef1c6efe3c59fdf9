"""Contrast about mid grey in a log encoding (Unity's ``ColorGradeContrast``): LogC, ACEScc or ACEScct, each folded
into as few operations as the context allows (:mod:`torchgrade.runtime.variants`).
"""

from __future__ import annotations

import math

import torch

from ..base.images import HALF_MAX
from ..base.params import Param, scalar_param
from ..color import (
    ACESCC_MIDGRAY,
    LOGC_A,
    LOGC_B,
    LOGC_C,
    LOGC_D,
    aces_to_acescc,
    acescc_to_aces,
    acescct_to_linear,
    convert,
    linear_to_acescct,
)
from ..runtime import affine, folded
from ..runtime.variants import formula

__all__ = ["contrast_space", "log_contrast", "logc_contrast", "acescc_contrast", "contrast"]


def contrast_space(aces: bool = False, log_space: str = "acescc") -> tuple:
    """``(encoding, into, out of)``: the log encoding contrast is graded in, the matrix (a :data:`~torchgrade.color.MATRICES`
    name) from linear Rec.709 into its primaries and the one from them to the grade's working space (None: none).

    Examples:
        >>> contrast_space(), contrast_space(True), contrast_space(True, "acescct")
        (('logc', None, None), ('acescc', 'srgb_to_ap0', 'ap0_to_ap1'), ('acescct', 'srgb_to_ap1', None))
    """
    if not aces:
        return "logc", None, None
    if log_space == "acescct":
        return "acescct", "srgb_to_ap1", None
    return "acescc", "srgb_to_ap0", "ap0_to_ap1"


def log_contrast(image: torch.Tensor, amount: Param, encoding: str = "logc") -> torch.Tensor:
    """Contrast about mid grey in ``encoding`` (``"logc"``, ``"acescc"`` or ``"acescct"``) on linear values in
    that encoding's primaries: ``(log(x) - 0.4135884) · (1 + amount/100) + 0.4135884``, decoded back.

    In LogC, ``c log10(a x + b) + d``, the encode, the scaling and the decode fold into one power:
    ``((a x + b)^k · 10^((d - 0.4135884)(k - 1) / c) - b) / a``.

    Examples:
        >>> # in a pure log encoding x -> 0.18 (x / 0.18)^k: grey is the pivot, 1.0 goes to 0.18 (1 / 0.18)^1.5
        >>> [round(v, 3) for v in log_contrast(torch.tensor([0.18, 1.0]), 50.0, "acescc").tolist()]
        [0.18, 2.357]
    """
    k = folded(_contrast_slope, amount, like=image, host="untracked")
    if encoding == "acescct":
        return acescct_to_linear((linear_to_acescct(image) - ACESCC_MIDGRAY) * k + ACESCC_MIDGRAY)
    if encoding == "acescc":
        return acescc_contrast(image, k)
    return logc_contrast(image, k)


@formula
def logc_contrast(image: torch.Tensor, k) -> torch.Tensor:
    """:func:`log_contrast` in LogC with slope ``k``, as one power: ``((a x + b)^k · 10^((d - 0.4135884)(k - 1) / c) - b) / a``.

    Examples:
        >>> round(float(logc_contrast(torch.tensor(0.18), torch.tensor(1.0))), 4)  # a slope of 1 changes nothing
        0.18
    """
    base = affine(image, LOGC_A, LOGC_B).clamp_min(torch.finfo(image.dtype).tiny)
    gain = torch.pow(10.0, (LOGC_D - ACESCC_MIDGRAY) * (k - 1.0) / LOGC_C) / LOGC_A
    return affine(base**k * gain, 1.0, -LOGC_B / LOGC_A)


@logc_contrast.variant("export")
def _logc_contrast_exported(image: torch.Tensor, k) -> torch.Tensor:
    """The power as ``exp(k ln(base) + ln(gain))``: a ``Log`` and an ``Exp`` cost less than half a ``Pow``
    (``benchmarks/results/onnx_ops.md``)."""
    base = affine(image, LOGC_A, LOGC_B).clamp_min(torch.finfo(image.dtype).tiny)
    log_gain = math.log(10.0) * (LOGC_D - ACESCC_MIDGRAY) / LOGC_C * (k - 1.0)
    return (torch.exp(torch.log(base) * k + log_gain) - LOGC_B) / LOGC_A


def _contrast_slope(amount: Param, *, like: torch.Tensor) -> torch.Tensor:
    """The slope ``k = 1 + amount / 100`` of :func:`log_contrast` (made once for a plain number, ``runtime.folded``).

    Examples:
        >>> _contrast_slope(50.0, like=torch.zeros(())).item()
        1.5
    """
    return 1.0 + scalar_param(amount, like, "contrast") * 0.01


_ACESCC_PIVOT_STOPS = ACESCC_MIDGRAY * 17.52 - 9.72
"""ACEScc's pivot as ``log2`` of linear (``log2(0.18)``): the code ``(log2(x) + 9.72) / 17.52`` at ``ACESCC_MIDGRAY``."""


@formula
def acescc_contrast(image: torch.Tensor, k) -> torch.Tensor:
    """:func:`log_contrast` in ACEScc with slope ``k``: encode, scale about the pivot, decode.

    Examples:
        >>> round(float(acescc_contrast(torch.tensor(0.18), torch.tensor(1.5))), 4)  # grey is the pivot
        0.18
    """
    return acescc_to_aces((aces_to_acescc(image) - ACESCC_MIDGRAY) * k + ACESCC_MIDGRAY)


@acescc_contrast.variant("untracked")
def _acescc_contrast_in_place(image: torch.Tensor, k) -> torch.Tensor:
    """The encode, the scaling and the decode folded into one power of two, computed in place.

    ``min(2^(k log2(2u) + p - k(1 + p)), 65504)``, that is ``2^min((log2(u) - p) k + p, log2(65504))``, with ``p``
    the pivot in stops and ``2u = x + max(x, 2^-15)`` twice the encode's ``u = max(x, 2^-16 + x/2)`` on ``x`` clamped
    to [0, 65504] (its two segments, :func:`~torchgrade.color.aces_to_acescc`); the decode's low segment
    ``(v - 2^-16)·2`` is below ``v`` exactly where ``v < 2^-15``, so the decode is ``2v - max(v, 2^-15)``.
    """
    x = image.clamp(0.0, HALF_MAX)
    offset = _ACESCC_PIVOT_STOPS - k * (1.0 + _ACESCC_PIVOT_STOPS)
    # bounded after the power: in float16 log2(65504) rounds to 16, whose power is infinite
    value = x.clamp_min(2.0**-15).add_(x).log2_().mul_(k).add_(offset).exp2_().clamp_max_(HALF_MAX)
    return value.clamp_min(2.0**-15).lerp_(value, 2.0)  # m + 2(v - m) = 2v - m


@acescc_contrast.variant("export")
def _acescc_contrast_folded(image: torch.Tensor, k) -> torch.Tensor:
    """The in-place form's folding with min and max of two branches as clamps: one ``Log``, one ``Exp``, no comparison
    or ``Where`` (their costs on onnxruntime's CPU: ``benchmarks/results/onnx_ops.md``).

    ``s = x + max(x, 2^-15)`` with ``x`` clamped to [0, 65504] is twice the encode's ``max(x, 2^-16 + x/2)``, rounded
    alike; ``v = exp(min(k ln s + ((1 - k) p - k) ln 2, ln 65504))`` the scaled code decoded, with ``p`` the pivot
    in stops; the decode's ``min(v, (v - 2^-16)·2)`` is ``2v - max(v, 2^-15)``, again with the same rounding.
    """
    x = image.clamp(0.0, HALF_MAX)
    doubled = x + x.clamp_min(2.0**-15)
    offset = ((1.0 - k) * _ACESCC_PIVOT_STOPS - k) * math.log(2.0)
    value = torch.exp((torch.log(doubled) * k + offset).clamp_max(math.log(HALF_MAX)))
    return 2.0 * value - value.clamp_min(2.0**-15)


def contrast(image: torch.Tensor, amount: Param, aces: bool = False, log_space: str = "acescc") -> torch.Tensor:
    """Contrast about mid grey in log space (:func:`log_contrast` in the encoding of :func:`contrast_space`).

    Linear mode uses LogC and returns linear Rec.709; ``aces=True`` uses ACEScc and returns ACEScg
    (Unity ``ColorGradingContrast``); ``log_space="acescct"`` uses ACEScct (S-2016-001) on ACEScg, whose
    linear toe below 2^-7 keeps shadows from the log's steep fall.

    Examples:
        >>> out = contrast(torch.tensor([0.05, 1.0, 1.0]).reshape(3, 1, 1), 50.0).flatten()
        >>> bool(out[0] < 0.05 and out[1] > 1.0)  # shadows darker, highlights brighter
        True
    """
    encoding, into, out_of = contrast_space(aces, log_space)
    x = image if into is None else convert(image, into)
    x = log_contrast(x, amount, encoding)
    return x if out_of is None else convert(x, out_of)
