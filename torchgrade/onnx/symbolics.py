"""Symbolic functions the TorchScript-based ONNX exporter lacks or gets wrong for ops torchgrade uses.

:func:`symbolics` registers them for the duration of one export: ``exp2``, ``expm1``, ``rad2deg``,
``frac``, Python's ``//`` on sizes (the stock symbolic truncates), ``pow`` by a constant (without ``Pow``),
``movedim`` with negative dimensions, ``nan_to_num`` (the stock symbolic casts the frame to float64 to find
infinities), ``addcmul`` (products and a sum in the graph's dtype) and ``lerp`` by a constant weight (without a
select).

These are the export rules of the library's formulas: each formula is written once, and where an ONNX runtime runs
another form of one of its operations faster, the exporter writes that form (``benchmarks/results/onnx_ops.md``).

Examples:
    >>> sorted(SYMBOLICS)[:3]
    ['aten::addcmul', 'aten::exp2', 'aten::expm1']
"""

from __future__ import annotations

import contextlib
import math
from typing import Callable

import torch

__all__ = ["SYMBOLICS", "symbolics"]


def _constant(g, value: float):
    return g.op("Constant", value_t=torch.tensor(value, dtype=torch.float32))


def _exp2(g, x):
    return g.op("Exp", g.op("Mul", x, _constant(g, math.log(2.0))))


def _expm1(g, x):
    return g.op("Sub", g.op("Exp", x), _constant(g, 1.0))


def _rad2deg(g, x):
    return g.op("Mul", x, _constant(g, 180.0 / math.pi))


def _frac(g, x):
    truncated = g.op("Mul", g.op("Sign", x), g.op("Floor", g.op("Abs", x)))
    return g.op("Sub", x, truncated)


def _floor_divide(g, a, b):
    """Python's ``//``, rounding down (the stock symbolic truncates, so ``-(-n // 2)`` came out wrong)."""
    from torch.onnx import symbolic_helper

    if symbolic_helper._is_fp(a) or symbolic_helper._is_fp(b):
        return g.op("Floor", g.op("Div", a, b))
    return g.op("Div", g.op("Sub", a, g.op("Mod", a, b, fmod_i=0)), b)


def _dims(value) -> list:
    from torch.onnx import symbolic_helper

    return torch.as_tensor(symbolic_helper._maybe_get_const(value, "t")).reshape(-1).tolist()


def _movedim(g, x, source, destination):
    """``movedim`` with negative dimensions (the stock symbolic writes them into the permutation)."""
    from torch.onnx import symbolic_helper

    rank = symbolic_helper._get_tensor_rank(x)
    moved = dict(zip((d % rank for d in _dims(destination)), (s % rank for s in _dims(source))))
    rest = iter(d for d in range(rank) if d not in moved.values())
    perm = [moved[d] if d in moved else next(rest) for d in range(rank)]
    return g.op("Transpose", x, perm_i=perm)


_SCALAR_DTYPES = {"Float": torch.float32, "Double": torch.float64, "Half": torch.float16, "BFloat16": torch.bfloat16}


def _nan_to_num(g, x, nan, posinf, neginf):
    """``nan_to_num`` as ``Where(IsNaN(x), nan, Clip(x, lowest, highest))`` when the infinities take the dtype's
    range (PyTorch's default): three nodes where the stock symbolic writes eleven, two of them float64 casts of the
    frame. Other replacements of infinities are chosen with ``IsInf``."""
    from torch.onnx import symbolic_helper

    dtype = _SCALAR_DTYPES[x.type().scalarType()]

    def value(given, default: float):
        number = default if symbolic_helper._is_none(given) else symbolic_helper._get_const(given, "f", "nan_to_num")
        return g.op("Constant", value_t=torch.tensor(number, dtype=dtype))

    finfo = torch.finfo(dtype)
    if symbolic_helper._is_none(posinf) and symbolic_helper._is_none(neginf):
        finite = g.op("Clip", x, value(neginf, finfo.min), value(posinf, finfo.max))
    else:
        finite = g.op("Where", g.op("IsInf", x, detect_negative_i=0), value(posinf, finfo.max), x)
        finite = g.op("Where", g.op("IsInf", x, detect_positive_i=0), value(neginf, finfo.min), finite)
    return g.op("Where", g.op("IsNaN", x), value(nan, 0.0), finite)


def _pow(g, x, exponent):
    """``x ** exponent``; a constant exponent 0 as ones of ``x``'s shape (``x ** 0`` is 1 for every ``x``, NaN and
    infinities too), 1 as ``x``, 2 or 3 as products, 0.5 as ``Sqrt`` (each correctly rounded, as
    ``Pow`` is), any other that is not a whole number as ``Exp(e · Log(x))`` (to a few ulps of the power; the same
    NaN for a negative base, 0 and infinity at 0), and so is an exponent that is a graph input where the graph shows
    the base positive (:func:`_sign`: a slope of LogC or ACEScc contrast given as an input): onnxruntime's CPU runs a
    ``Pow`` many times as long as a ``Mul`` or a ``Sqrt``, twice as long as a ``Log`` and an ``Exp``
    (``benchmarks/results/onnx_ops.md``)."""
    from torch.onnx import symbolic_helper, symbolic_opset9

    value = symbolic_helper._maybe_get_const(exponent, "t")
    if symbolic_helper._is_fp(x) and not isinstance(value, torch.Tensor) and _sign(x) > 0:
        return g.op("Exp", g.op("Mul", g.op("Log", x), exponent))  # a graph input's exponent of a positive base
    if not symbolic_helper._is_fp(x) or not isinstance(value, torch.Tensor) or value.numel() != 1:
        return symbolic_opset9.pow(g, x, exponent)
    power = float(value)
    if power == 0.0:
        return g.op("Expand", _constant_like(g, 1.0, x), g.op("Shape", x))
    if power == 1.0:
        return x
    if power in (2.0, 3.0):
        square = g.op("Mul", x, x)
        return square if power == 2.0 else g.op("Mul", square, x)
    if power == 0.5:
        return g.op("Sqrt", x)
    if not power.is_integer():
        return g.op("Exp", g.op("Mul", g.op("Log", x), _constant_like(g, power, x)))
    return symbolic_opset9.pow(g, x, exponent)


def _sign(x, depth: int = 4) -> int:
    """1 where the graph shows ``x`` positive, 0 where it shows it at least 0, -1 where it shows neither: a ``Clip`` or
    ``Max`` by a constant bound, a ``Relu``, a sum of such."""
    from torch.onnx import symbolic_helper

    node = x.node()
    kind = node.kind()
    if depth == 0:
        return -1
    if kind == "onnx::Relu":
        return 0
    if kind in ("onnx::Clip", "onnx::Max") and len(list(node.inputs())) > 1:
        bound = list(node.inputs())[1]
        while bound.node().kind() == "onnx::Cast":  # a Python number's bound, cast to the graph's dtype
            bound = bound.node().input()
        bound = symbolic_helper._maybe_get_const(bound, "f")
        if isinstance(bound, (int, float)):
            return 1 if bound > 0 else 0 if bound == 0 else -1
        return -1
    if kind == "onnx::Add":
        signs = sorted(_sign(term, depth - 1) for term in node.inputs())
        return -1 if signs[0] < 0 else signs[-1]
    return -1


def _constant_like(g, number: float, x):
    """A scalar ``Constant`` in ``x``'s float dtype (float32 where the graph does not say)."""
    dtype = _SCALAR_DTYPES.get(x.type().scalarType(), torch.float32)
    return g.op("Constant", value_t=torch.tensor(number, dtype=dtype))


def _addcmul(g, x, tensor1, tensor2, value):
    """``x + value · tensor1 · tensor2`` as products and a sum, ``value`` left out at 1 and otherwise a constant in the
    graph's dtype (the stock symbolic multiplies by a float32 ``value`` whatever the graph's dtype, and by 1 too)."""
    from torch.onnx import symbolic_helper

    product = g.op("Mul", tensor1, tensor2)
    number = symbolic_helper._maybe_get_const(value, "f")
    if not isinstance(number, (int, float)) or number != 1:
        product = g.op("Mul", product, _constant_like(g, float(number), x) if isinstance(number, (int, float)) else value)
    return g.op("Add", x, product)


def _lerp(g, start, end, weight):
    """``lerp`` by a constant weight ``w`` as PyTorch rounds it, the branch picked here: ``start + w (end - start)`` for
    ``|w| < 0.5``, else ``end + (w - 1)(end - start)`` (a product by 1 left out); the stock symbolic writes both and a
    select. A weight that is a tensor takes the stock symbolic."""
    from torch.onnx import symbolic_helper, symbolic_opset9

    value = symbolic_helper._maybe_get_const(weight, "t")
    if not symbolic_helper._is_fp(start) or not isinstance(value, torch.Tensor) or value.numel() != 1:
        return symbolic_opset9.lerp(g, start, end, weight)
    w = float(value)
    base, factor = (start, w) if abs(w) < 0.5 else (end, w - 1.0)
    difference = g.op("Sub", end, start)
    return g.op("Add", base, difference if factor == 1.0 else g.op("Mul", difference, _constant_like(g, factor, start)))


SYMBOLICS: dict[str, Callable] = {
    "aten::pow": _pow,
    "aten::addcmul": _addcmul,
    "aten::lerp": _lerp,
    "aten::exp2": _exp2,
    "aten::expm1": _expm1,
    "aten::rad2deg": _rad2deg,
    "aten::frac": _frac,
    "aten::movedim": _movedim,
    "aten::floor_divide": _floor_divide,
    "aten::floordiv": _floor_divide,
    "aten::nan_to_num": _nan_to_num,
}


@contextlib.contextmanager
def symbolics(opset: int):
    """Register torchgrade's symbolic functions for one export, and remove them afterwards.

    Examples:
        >>> with symbolics(17):
        ...     pass
    """
    for name, function in SYMBOLICS.items():
        torch.onnx.register_custom_op_symbolic(name, function, opset)
    try:
        yield
    finally:
        for name in SYMBOLICS:
            torch.onnx.unregister_custom_op_symbolic(name, opset)
