"""Transfer functions (encodings) on tensors: sRGB, LogC, ACEScc, ACEScct, SMPTE ST 2084 (PQ), BT.2100 HLG,
and the guarded power and square root they are built on.

Every encoding is differentiable with finite gradients at 0 and at very large values: branches are
computed with ``torch.where`` on guarded arguments, so the branch not taken never produces an
infinite gradient.
"""

from __future__ import annotations

import math

import torch

from ..runtime.constants import affine

__all__ = [
    "safe_pow", "safe_sqrt", "linear_to_srgb", "srgb_to_linear", "linear_to_logc", "logc_to_linear", "aces_to_acescc", "acescc_to_aces", "linear_to_pq", "pq_to_linear", "hlg_oetf", "hlg_inverse_oetf", "linear_to_acescct", "acescct_to_linear", "LOGC_CUT", "LOGC_E", "ACESCC_MIDGRAY", "ACESCC_MAX", "PQ_M1", "PQ_C1", "PQ_PEAK", "PQ_FOOT", "HLG_A", "HLG_B", "HLG_C", "ACESCCT_CUT_LINEAR", "ACESCCT_CUT_LOG", "ACESCCT_A", "LOGC_A", "LOGC_B", "LOGC_C", "LOGC_D", "LOGC_F", "PQ_M2", "PQ_C2", "PQ_C3", "ACESCCT_B",
]


def safe_pow(x: torch.Tensor, exponent) -> torch.Tensor:
    """``max(x, 0) ** exponent`` for ``exponent > 0``, with a finite gradient at 0 (HLSL ``PositivePow`` on clamped
    input): ``relu(x) ** exponent``. The power's slope ``e x^(e-1)`` is infinite at 0 for ``e < 1``; ``relu``'s
    backward selects 0 wherever its output is 0, which no product with that infinity undoes. Exported as ``Relu`` and
    ``exp(e log x)`` (``torchgrade.onnx.symbolics``: a ``Pow`` costs onnxruntime's CPU twice a ``Log`` and an ``Exp``).

    Examples:
        >>> safe_pow(torch.tensor([-1.0, 0.0, 4.0]), 0.5).tolist()
        [0.0, 0.0, 2.0]
    """
    return torch.relu(x) ** exponent


def safe_sqrt(x: torch.Tensor) -> torch.Tensor:
    """``sqrt(max(x, 0))`` with gradient 0 (not Inf) at 0 (see :func:`safe_pow`).

    Examples:
        >>> safe_sqrt(torch.tensor([-4.0, 0.0, 9.0])).tolist()
        [0.0, 0.0, 3.0]
    """
    return torch.relu(x).sqrt()


def linear_to_srgb(image: torch.Tensor) -> torch.Tensor:
    """IEC 61966-2-1 sRGB encoding: ``12.92 x`` below 0.0031308, else ``1.055 x^(1/2.4) - 0.055``.

    Examples:
        >>> [round(v, 4) for v in linear_to_srgb(torch.tensor([0.0, 0.18, 1.0])).flatten().tolist()]
        [0.0, 0.4614, 1.0]
    """
    high = affine(image.clamp_min(0.0031308) ** (1.0 / 2.4), 1.055, -0.055)
    return torch.where(image <= 0.0031308, 12.92 * image, high)


def srgb_to_linear(image: torch.Tensor) -> torch.Tensor:
    """IEC 61966-2-1 sRGB decoding: ``c / 12.92`` up to 0.04045, else ``((c + 0.055) / 1.055)^2.4``.

    Examples:
        >>> [round(v, 4) for v in srgb_to_linear(torch.tensor([0.0, 0.5, 1.0])).flatten().tolist()]
        [0.0, 0.214, 1.0]
    """
    high = affine(image.clamp_min(0.04045), 1.0 / 1.055, 0.055 / 1.055) ** 2.4
    return torch.where(image <= 0.04045, image / 12.92, high)


# ARRI LogC (v3) curve with the constants Unity uses (ARRI's EI 1000 table), and Unity's fast form:
# the logarithmic segment everywhere, ``c log10(a x + b) + d``. Its range tops out at ~58.86.
LOGC_CUT, LOGC_A, LOGC_B, LOGC_C, LOGC_D = 0.011361, 5.555556, 0.047996, 0.244161, 0.386036
LOGC_E, LOGC_F = 5.301883, 0.092819


def linear_to_logc(image: torch.Tensor) -> torch.Tensor:
    """Unity ``LinearToLogC``: ``c log10(max(a x + b, tiny)) + d``.

    Inputs below ``-b/a`` (≈ -0.0086, far out of gamut) all encode to the floor, as in Unity,
    where the ``max(…, 0)`` gives ``log10(0) = -inf``; the floor keeps it finite.

    Examples:
        >>> [round(v, 4) for v in linear_to_logc(torch.tensor([0.0, 0.18])).flatten().tolist()]
        [0.064, 0.391]
    """
    tiny = torch.finfo(image.dtype).tiny
    return affine(torch.log10(affine(image, LOGC_A, LOGC_B).clamp_min(tiny)), LOGC_C, LOGC_D)


def logc_to_linear(image: torch.Tensor) -> torch.Tensor:
    """Unity ``LogCToLinear``: ``(10^((x - d) / c) - b) / a``.

    Examples:
        >>> round(float(logc_to_linear(torch.tensor(0.391007))), 4)
        0.18
    """
    return (torch.pow(10.0, (image - LOGC_D) / LOGC_C) - LOGC_B) / LOGC_A


ACESCC_MIDGRAY = 0.4135884
"""ACEScc code value of 18% grey; Unity uses it as the contrast pivot in LogC too."""
ACESCC_MAX = 1.4679964
_HALF_MAX = 65504.0
_ACESCC_LOW_KNEE = (9.72 - 15.0) / 17.52


def aces_to_acescc(image: torch.Tensor) -> torch.Tensor:
    """ACES2065-1 -> ACEScc (S-2014-003 §4.4), input clamped to [0, 65504] as Unity does.

    The standard's two segments, ``log2(2^-16 + x/2)`` below ``2^-15`` and ``log2(x)`` from it, are one logarithm of
    the larger argument: ``2^-16 + x/2 < x`` exactly from ``2^-15`` up. No comparison and select, in any graph.

    Examples:
        >>> round(float(aces_to_acescc(torch.tensor(0.18))), 4)  # ACESCC_MIDGRAY
        0.4136
    """
    x = image.clamp(0.0, _HALF_MAX)
    return (torch.log2(torch.maximum(x, affine(x, 0.5, 2.0**-16))) + 9.72) / 17.52


_ACESCC_TOP = (math.log2(_HALF_MAX) + 9.72) / 17.52
"""The ACEScc code of 65504, a Python float (``torch.compile`` traces no tensor read-back)."""


def acescc_to_aces(image: torch.Tensor) -> torch.Tensor:
    """ACEScc -> ACES2065-1 (S-2014-003 §4.4); saturates at 65504 like Unity.

    The low segment's ``(v - 2^-16)·2`` is below ``v = 2^(17.52 c - 9.72)`` exactly where ``v < 2^-15``: the smaller
    of the two is the standard's value.

    Examples:
        >>> round(float(acescc_to_aces(torch.tensor(0.4135884))), 4)
        0.18
    """
    value = torch.exp2(affine(image.clamp(max=_ACESCC_TOP), 17.52, -9.72))
    return torch.minimum(value, affine(value, 2.0, -(2.0**-15)))


PQ_M1, PQ_M2 = 2610.0 / 16384.0, 2523.0 / 4096.0 * 128.0
PQ_C1, PQ_C2, PQ_C3 = 3424.0 / 4096.0, 2413.0 / 4096.0 * 32.0, 2392.0 / 4096.0 * 32.0
PQ_PEAK = 10000.0
"""Luminance (cd/m²) of PQ code value 1."""
PQ_FOOT = 1e-12
"""The share of :data:`PQ_PEAK` (1e-8 cd/m²) below which :func:`linear_to_pq` takes the chord of ``Y^m1`` from 0."""


def linear_to_pq(image: torch.Tensor, reference: float | torch.Tensor = 100.0) -> torch.Tensor:
    """SMPTE ST 2084 inverse EOTF of ``image * reference`` cd/m², negatives clamped to 0.

    ``E' = ((c1 + c2 Y^m1) / (1 + c3 Y^m1))^m2`` with ``Y = image * reference / 10000``; the
    default ``reference`` puts 1.0 at 100 cd/m² (OpenColorIO's scene/display convention).

    Below :data:`PQ_FOOT` (1e-8 cd/m²) ``Y^m1`` is its chord from 0, ``Y · PQ_FOOT^(m1 - 1)``: the power's slope,
    ``m1 Y^(m1 - 1)`` with ``m1 = 0.159``, is infinite at 0, and Unity's HDR range reduction, which decodes a
    black it lifted, passed it on (gradients of 8e30 at float32's smallest denormal). The chord moves codes by at most
    4.7e-6 (a 12-bit code is 2.4e-4) and keeps the slope below 1.4e7 a unit of ``Y``.

    Examples:
        >>> round(float(linear_to_pq(torch.tensor(1.0))), 4)  # 100 cd/m²
        0.5081
        >>> float(linear_to_pq(torch.tensor(10000.0), reference=1.0))
        1.0
    """
    y = image * (reference / PQ_PEAK)
    y_m1 = safe_pow(y.clamp_min(PQ_FOOT), PQ_M1) * (y.clamp(0.0, PQ_FOOT) / PQ_FOOT)
    return safe_pow((PQ_C1 + PQ_C2 * y_m1) / (1.0 + PQ_C3 * y_m1), PQ_M2)


def pq_to_linear(code: torch.Tensor, reference: float = 100.0) -> torch.Tensor:
    """SMPTE ST 2084 EOTF in units of ``reference`` cd/m²:
    ``10000 (max(E'^(1/m2) - c1, 0) / (c2 - c3 E'^(1/m2)))^(1/m1)``.

    Examples:
        >>> round(float(pq_to_linear(torch.tensor(0.5081))), 2)
        1.0
        >>> float(pq_to_linear(torch.tensor(1.0), reference=1.0))
        10000.0
    """
    e = safe_pow(code.clamp(max=1.0), 1.0 / PQ_M2)
    return PQ_PEAK / reference * safe_pow((e - PQ_C1).clamp_min(0.0) / (PQ_C2 - PQ_C3 * e), 1.0 / PQ_M1)


# ITU-R BT.2100 HLG constants.
HLG_A = 0.17883277
HLG_B = 1.0 - 4.0 * HLG_A
HLG_C = 0.5 - HLG_A * math.log(4.0 * HLG_A)


def hlg_oetf(image: torch.Tensor) -> torch.Tensor:
    """ITU-R BT.2100 HLG OETF of scene light ``E`` in ``[0, 1]``: ``sqrt(3 E)`` up to 1/12, else ``a ln(12 E - b) + c``.

    Examples:
        >>> [round(v, 4) for v in hlg_oetf(torch.tensor([1.0 / 12.0, 1.0])).tolist()]
        [0.5, 1.0]
    """
    low = safe_sqrt(3.0 * image)
    high = HLG_A * torch.log((12.0 * image).clamp_min(1.0) - HLG_B) + HLG_C
    return torch.where(image <= 1.0 / 12.0, low, high)


def hlg_inverse_oetf(code: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`hlg_oetf`: ``E'²/3`` up to 0.5, else ``(exp((E' - c) / a) + b) / 12``.

    Examples:
        >>> [round(v, 4) for v in hlg_inverse_oetf(torch.tensor([0.5, 1.0])).tolist()]
        [0.0833, 1.0]
    """
    low = code.clamp_min(0.0) ** 2 / 3.0
    high = (torch.exp((code.clamp(0.5, 2.0) - HLG_C) / HLG_A) + HLG_B) / 12.0
    return torch.where(code <= 0.5, low, high)


# ACEScct (S-2016-001): a linear toe below 2^-7, ACEScc's log segment above.
ACESCCT_CUT_LINEAR = 0.0078125
ACESCCT_CUT_LOG = 0.155251141552511
ACESCCT_A, ACESCCT_B = 10.5402377416545, 0.0729055341958355


def linear_to_acescct(image: torch.Tensor) -> torch.Tensor:
    """ACEScg (AP1) -> ACEScct: ``A x + B`` up to 2^-7, else ``(log2(x) + 9.72) / 17.52`` (S-2016-001).

    The linear toe is the tangent of the log segment at the cut, above the (concave) logarithm everywhere else, and
    the logarithm of ``max(x, 2^-7)`` is constant below the cut: the smaller of the two is the standard's value. No
    comparison and select, in any graph (``benchmarks/results/onnx_ops.md``).

    Examples:
        >>> [round(v, 4) for v in linear_to_acescct(torch.tensor([0.0, 0.18])).tolist()]
        [0.0729, 0.4136]
    """
    log = (torch.log2(image.clamp_min(ACESCCT_CUT_LINEAR)) + 9.72) / 17.52
    return torch.minimum(affine(image, ACESCCT_A, ACESCCT_B), log)


def acescct_to_linear(code: torch.Tensor) -> torch.Tensor:
    """ACEScct -> ACEScg (AP1), the inverse of :func:`linear_to_acescct`, saturating at 65504 like ACEScc.

    The segments meet at the cut: each is evaluated on its own side of it, clamped there, and the two added less their
    common value; no comparison or select (``benchmarks/results/onnx_ops.md``).

    Examples:
        >>> round(float(acescct_to_linear(torch.tensor(0.4135884))), 4)
        0.18
    """
    log = torch.exp2(affine(code.clamp(ACESCCT_CUT_LOG, _ACESCC_TOP), 17.52, -9.72))
    return log + affine(code.clamp_max(ACESCCT_CUT_LOG), 1.0 / ACESCCT_A, -ACESCCT_B / ACESCCT_A - ACESCCT_CUT_LINEAR)
