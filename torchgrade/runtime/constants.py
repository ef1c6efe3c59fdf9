"""Constants on the device of the data, made once: no host-to-device copy per frame.

``torch.tensor(0.3, device="cuda")`` or ``MATRIX.to(image)`` copies from host memory at every call (1,419
pageable copies a 4K frame of the cinematic look on an H200). :func:`constant` keeps each constant tensor per
value, dtype and device, so a frame after the first builds nothing from Python data. While tracing, compiling
or exporting it makes the tensor afresh, which the graph records as a constant.

Tables derived from sizes (a blur's kernel, a padding's indices) are kept the same way by :func:`device_cached`.
Cached tensors are shared: callers never modify them in place, and public functions hand out copies
(:func:`~torchgrade.color.matrix`).

Examples:
    >>> import torch
    >>> like = torch.zeros(1, dtype=torch.float64)
    >>> a = constant((1.0, 2.0), like)
    >>> a.tolist(), a.dtype, a is constant((1.0, 2.0), like)
    ([1.0, 2.0], torch.float64, True)
"""

from __future__ import annotations

import functools
import numbers

import torch

from .recording import is_tracing

__all__ = ["constant", "scalar", "where", "is_plain_number", "affine", "values_of", "device_cached", "folded", "CACHED_CONSTANTS"]

CACHED_CONSTANTS = 4096
"""Constants kept per kind (least recently used go first): a look holds tens; random controls are tensors, not cached."""


def constant(values, like: torch.Tensor) -> torch.Tensor:
    """``values`` (a number or nested tuples of numbers) as a tensor in ``like``'s dtype on its device, made once there.

    While compiling, the values are written into the graph, which Inductor makes a constant on the device (a
    tensor held by a module or a global would be an input of the graph instead, copied to the device at every
    call and keeping CUDA graphs out): module-level tensor constants keep their values as tuples
    (:func:`values_of`) for this.
    """
    if is_tracing():
        return torch.tensor(values, dtype=like.dtype, device=like.device)
    return _cached(values, like.dtype, like.device)


def scalar(value, like: torch.Tensor) -> torch.Tensor:
    """A plain number as the 0-d operand of an elementwise operation on ``like`` (``torch.add``, ``torch.div``,
    ``torch.fmax``, ... where the operation takes no number): a 0-d CPU tensor in ``like``'s dtype, made once. A tuple
    of numbers gives a CPU tensor whose elements, unbound, are such operands.

    CUDA passes a 0-d CPU operand of a two-operand kernel to it as an argument (no copy) and keeps the kernel
    vectorised; a 0-d tensor on the device is an operand broadcast to every element, which PyTorch's CUDA kernels read
    through per-element offsets (their slower, unvectorised loop). Not for ``torch.where``, which copies a CPU operand
    to the device at every call, nor for the first operands of ``addcmul``, which CUDA refuses: :func:`constant`
    there. While tracing, compiling or exporting, a :func:`constant` (a graph keeps its constants on its device).

    Examples:
        >>> import torch
        >>> x = torch.tensor([1.0, 4.0])
        >>> scalar(2.0, x).device.type, torch.div(scalar(2.0, x), x).tolist()
        ('cpu', [2.0, 0.5])
    """
    if is_tracing():
        return constant(value, like)
    return _cached(value, like.dtype, _CPU)


def where(condition: torch.Tensor, a, b) -> torch.Tensor:
    """``torch.where(condition, a, b)`` with a plain number among ``a`` and ``b`` as a :func:`constant` of the
    other's dtype on its device: as a number, ``torch.where`` makes a new 0-d tensor at every call (a fill kernel on
    a GPU). While tracing, compiling or exporting, ``torch.where`` itself (the graph records the number).

    Examples:
        >>> import torch
        >>> where(torch.tensor([True, False]), 1.0, torch.tensor([5.0, 6.0])).tolist()
        [1.0, 6.0]
    """
    like = a if isinstance(a, torch.Tensor) else b
    if is_tracing() or not isinstance(like, torch.Tensor) or not like.is_floating_point():
        return torch.where(condition, a, b)
    a, b = (constant(float(v), like) if is_plain_number(v) else v for v in (a, b))
    return torch.where(condition, a, b)


def is_plain_number(value) -> bool:
    """Whether a control is a Python number (not a bool): arithmetic on it runs in Python, launching nothing on a device,
    where a tensor control (per sample, learnable) needs its operations on the data's device.

    Examples:
        >>> is_plain_number(0.5), is_plain_number(True), is_plain_number(torch.tensor(0.5))
        (True, False, False)
    """
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def affine(x: torch.Tensor, scale: float, offset: float) -> torch.Tensor:
    """``scale * x + offset`` of plain numbers as one operation, ``torch.add(offset, x, alpha=scale)`` with the offset a
    :func:`scalar` (a product and a sum are two passes over a frame, each a launch on a GPU). The offset takes
    ``x``'s dtype: for the working dtypes, float32 and float64.

    Examples:
        >>> import torch
        >>> affine(torch.tensor([1.0, 2.0]), 3.0, 0.5).tolist()
        [3.5, 6.5]
    """
    return torch.add(scalar(offset, x), x, alpha=scale)


_CPU = torch.device("cpu")


def _cached(values, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """``torch.tensor(values)`` in ``dtype`` on ``device``, made once."""
    return _made(values, dtype, device)


@functools.lru_cache(maxsize=CACHED_CONSTANTS)
def _made(values, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    return _kept(torch.tensor, values, dtype=dtype, device=device)


def _kept(make, *arguments, **keywords) -> torch.Tensor:
    """``make(*arguments, **keywords)``, made outside inference mode (an inference tensor cannot be saved for a later
    backward pass)."""
    with torch.inference_mode(False):
        return make(*arguments, **keywords)


def values_of(tensor: torch.Tensor):
    """A constant tensor's values as nested tuples of Python floats, for :func:`constant`.

    Examples:
        >>> values_of(torch.eye(2, dtype=torch.float64))
        ((1.0, 0.0), (0.0, 1.0))
    """
    return _nested_tuple(tensor.tolist())


def device_cached(make):
    """Decorate ``make(*arguments)``, a function of hashable arguments (sizes, a ``torch.device``, a dtype) that
    builds a constant tensor, so that each tensor is built once; while tracing, compiling or exporting it is
    built afresh (a graph records how, and an exported graph keeps sizes symbolic).

    Examples:
        >>> import torch
        >>> @device_cached
        ... def ramp(n, device):
        ...     return torch.arange(n, device=device)
        >>> ramp(3, torch.device("cpu")) is ramp(3, torch.device("cpu"))
        True
    """

    @functools.lru_cache(maxsize=CACHED_CONSTANTS)
    def cached(*arguments):
        return _kept(make, *arguments)

    @functools.wraps(make)
    def call(*arguments):
        return make(*arguments) if is_tracing() else cached(*arguments)

    return call


def folded(function, *arguments, like: torch.Tensor, host: bool = False):
    """``function(*arguments, like=like)``, a small tensor of the controls (a colour matrix, gains), made once.

    With plain controls (numbers, strings, nested sequences, ``None``) the result is computed once in float64 on
    the CPU and kept, in ``like``'s dtype, on its device (:func:`constant`): a frame then launches nothing for it.
    With ``host``, kept on the CPU instead (:func:`scalar`), for a caller that takes its values as 0-d operands of
    two-operand operations. A tensor among the arguments (a per-sample or learnable control), or tracing, computes it
    on ``like`` as called.

    Examples:
        >>> import torch
        >>> def gain(stops, *, like):
        ...     return torch.exp2(torch.tensor(stops, dtype=like.dtype, device=like.device))
        >>> like = torch.zeros(1)
        >>> folded(gain, 2.0, like=like).item(), folded(gain, 2.0, like=like) is folded(gain, 2.0, like=like)
        (4.0, True)
        >>> folded(gain, 2.0, like=torch.zeros(1, device="meta"), host=True).device.type  # a 0-d operand on the host
        'cpu'
    """
    if is_tracing():
        return function(*arguments, like=like)
    try:
        key = _frozen(arguments)
    except TypeError:
        return function(*arguments, like=like)
    values = _float64_values(function, key)
    return None if values is None else (scalar if host else constant)(values, like)


@functools.lru_cache(maxsize=CACHED_CONSTANTS)
def _float64_values(function, arguments: tuple):
    result = function(*arguments, like=torch.zeros((), dtype=torch.float64))
    return None if result is None else values_of(result)


def _frozen(value):
    """``value`` with lists as tuples (a cache key); ``TypeError`` when it holds a tensor or anything unhashable."""
    if isinstance(value, torch.Tensor):
        raise TypeError("a tensor is not folded")
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(item) for item in value)
    hash(value)
    return value


def _nested_tuple(values):
    return tuple(_nested_tuple(v) for v in values) if isinstance(values, list) else values
