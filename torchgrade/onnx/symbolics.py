"""Symbolic functions the TorchScript-based ONNX exporter lacks or gets wrong for ops torchgrade uses.

:func:`symbolics` registers them for the duration of one export: ``exp2``, ``expm1``, ``rad2deg``,
``frac``, Python's ``//`` on sizes (the stock symbolic truncates), ``pow`` by 2, 3 and 0.5 (without ``Pow``), ``movedim`` with negative
dimensions, ``nan_to_num`` (the stock symbolic casts the frame to float64 to find infinities), and
``avg_pool2d`` with ``divisor_override`` (bloom's 2x2 sums, which the stock symbolic silently exports as means).

Examples:
    >>> sorted(SYMBOLICS)[:3]
    ['aten::avg_pool2d', 'aten::exp2', 'aten::expm1']
"""

from __future__ import annotations

import contextlib
import math

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


def _avg_pool2d(g, x, kernel_size, stride, padding, ceil_mode, count_include_pad, divisor_override):
    """``avg_pool2d``; with ``divisor_override`` (non-overlapping windows, no padding) a zero-padded sum.

    Sums pad the bottom and right edges to a multiple of the window (as ``ceil_mode`` does), average
    with ``AveragePool`` and scale by ``window / divisor``.
    """
    from torch.onnx import symbolic_helper

    kernel = symbolic_helper._maybe_get_const(kernel_size, "is")
    kernel = list(kernel) * 2 if len(kernel) == 1 else list(kernel)
    strides = symbolic_helper._maybe_get_const(stride, "is") or kernel
    strides = list(strides) * 2 if len(strides) == 1 else list(strides)
    pads = symbolic_helper._maybe_get_const(padding, "is")
    pads = list(pads) * 2 if len(pads) == 1 else list(pads)
    ceil = int(symbolic_helper._maybe_get_const(ceil_mode, "b"))
    include_pad = int(symbolic_helper._maybe_get_const(count_include_pad, "b"))
    divisor = None if symbolic_helper._is_none(divisor_override) else symbolic_helper._maybe_get_const(divisor_override, "i")
    if divisor is None:
        return g.op("AveragePool", x, kernel_shape_i=kernel, strides_i=strides, pads_i=pads + pads,
                    ceil_mode_i=ceil, count_include_pad_i=include_pad)
    if kernel != strides or any(pads):
        raise torch.onnx.errors.SymbolicValueError("avg_pool2d with divisor_override: only non-overlapping windows", x)
    window = torch.tensor(kernel, dtype=torch.int64)
    spatial = g.op("Slice", g.op("Shape", x), g.op("Constant", value_t=torch.tensor([2])),
                   g.op("Constant", value_t=torch.tensor([4])))
    window_t = g.op("Constant", value_t=window)
    remainder = g.op("Mod", g.op("Sub", window_t, g.op("Mod", spatial, window_t)), window_t)
    if not ceil:
        remainder = g.op("Mul", remainder, g.op("Constant", value_t=torch.tensor([0, 0])))
    pad_amounts = g.op("Concat", g.op("Constant", value_t=torch.zeros(6, dtype=torch.int64)), remainder, axis_i=0)
    padded = g.op("Pad", x, pad_amounts)
    mean = g.op("AveragePool", padded, kernel_shape_i=kernel, strides_i=strides)
    return g.op("Mul", mean, _constant(g, float(kernel[0] * kernel[1]) / divisor))


def _pow(g, x, exponent):
    """``x ** exponent``; a constant exponent 2 or 3 as products, 0.5 as ``Sqrt`` (each correctly rounded, as
    ``Pow`` is): onnxruntime's CPU runs a ``Pow`` many times as long as a ``Mul`` or a ``Sqrt`` (``benchmarks/results/onnx_ops.md``)."""
    from torch.onnx import symbolic_helper, symbolic_opset9

    value = symbolic_helper._maybe_get_const(exponent, "t")
    if not symbolic_helper._is_fp(x) or not isinstance(value, torch.Tensor) or value.numel() != 1:
        return symbolic_opset9.pow(g, x, exponent)
    power = float(value)
    if power in (2.0, 3.0):
        square = g.op("Mul", x, x)
        return square if power == 2.0 else g.op("Mul", square, x)
    if power == 0.5:
        return g.op("Sqrt", x)
    return symbolic_opset9.pow(g, x, exponent)


SYMBOLICS = {
    "aten::pow": _pow,
    "aten::exp2": _exp2,
    "aten::expm1": _expm1,
    "aten::rad2deg": _rad2deg,
    "aten::frac": _frac,
    "aten::movedim": _movedim,
    "aten::floor_divide": _floor_divide,
    "aten::floordiv": _floor_divide,
    "aten::avg_pool2d": _avg_pool2d,
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
