"""Contrast about mid grey in a log encoding (Unity's ``ColorGradeContrast``): LogC, ACEScc or ACEScct, the encode,
the scaling and the decode of LogC and ACEScc each folded into one power.
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
    acescct_to_linear,
    convert,
    linear_to_acescct,
)
from ..runtime import affine
from ..runtime.constants import is_plain_number

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
    k = 1.0 + amount * 0.01 if is_plain_number(amount) else 1.0 + scalar_param(amount, image, "contrast") * 0.01
    if encoding == "acescct":
        return acescct_to_linear((linear_to_acescct(image) - ACESCC_MIDGRAY) * k + ACESCC_MIDGRAY)
    if encoding == "acescc":
        return acescc_contrast(image, k)
    return logc_contrast(image, k)


_LOGC_GAIN_PER_SLOPE = math.log(10.0) * (LOGC_D - ACESCC_MIDGRAY) / LOGC_C
"""``ln`` of :func:`logc_contrast`'s gain per unit of ``k - 1``."""


def _exp(value):
    """``e^value`` of a number or a tensor (a per-sample or learnable slope's small tensor)."""
    return torch.exp(value) if isinstance(value, torch.Tensor) else math.exp(value)


def logc_contrast(image: torch.Tensor, k) -> torch.Tensor:
    """:func:`log_contrast` in LogC with slope ``k`` (a number or a tensor), as one power and a multiply-add:
    ``((a x + b)^k · 10^((d - 0.4135884)(k - 1) / c) - b) / a`` (exported as ``exp(k ln(a x + b))``, the base being
    positive: a ``Log`` and an ``Exp`` cost onnxruntime's CPU less than half a ``Pow``, :mod:`torchgrade.onnx.symbolics`).

    Examples:
        >>> round(float(logc_contrast(torch.tensor(0.18), 1.0)), 4)  # a slope of 1 changes nothing
        0.18
    """
    base = affine(image, LOGC_A, LOGC_B).clamp_min(torch.finfo(image.dtype).tiny)
    gain = _exp(_LOGC_GAIN_PER_SLOPE * (k - 1.0)) / LOGC_A
    if isinstance(gain, torch.Tensor):  # a product and a difference by a number: a 0-d CPU operand CUDA's addcmul refuses
        return base**k * gain - LOGC_B / LOGC_A
    return affine(base**k, gain, -LOGC_B / LOGC_A)


_ACESCC_PIVOT_STOPS = ACESCC_MIDGRAY * 17.52 - 9.72
"""ACEScc's pivot as ``log2`` of linear (``log2(0.18)``): the code ``(log2(x) + 9.72) / 17.52`` at ``ACESCC_MIDGRAY``."""


def acescc_contrast(image: torch.Tensor, k) -> torch.Tensor:
    """:func:`log_contrast` in ACEScc with slope ``k`` (a number or a tensor): encode, scale about the pivot, decode,
    folded into one power.

    ``s = x + max(x, 2^-15)`` with ``x`` clamped to [0, 65504] is twice the encode's ``max(x, 2^-16 + x/2)``
    (:func:`~torchgrade.color.aces_to_acescc`'s two segments), rounded alike; ``v = min(s^k · 2^((1 - k) p - k),
    65504)`` is the scaled code decoded, with ``p`` the pivot in stops (``s^k`` at most ``131008²``, finite in float32); the
    decode's low segment ``min(v, (v - 2^-16)·2)`` (:func:`~torchgrade.color.acescc_to_aces`) is ``2v - max(v, 2^-15)``,
    again with the same rounding, computed as ``lerp(max(v, 2^-15), v, 2)``, that is ``v + (v - max(v, 2^-15))`` (one
    operation, within 65504; exported as a subtraction and a sum, :mod:`torchgrade.onnx.symbolics`). No comparison or
    select.

    Examples:
        >>> round(float(acescc_contrast(torch.tensor(0.18), 1.5)), 4)  # grey is the pivot
        0.18
    """
    x = image.clamp(0.0, HALF_MAX)
    doubled = x + x.clamp_min(2.0**-15)
    gain = _exp(((1.0 - k) * _ACESCC_PIVOT_STOPS - k) * math.log(2.0))
    value = (doubled**k * gain).clamp_max(HALF_MAX)
    return torch.lerp(value.clamp_min(2.0**-15), value, 2.0)


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
