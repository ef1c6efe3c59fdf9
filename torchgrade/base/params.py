"""Parameters: a Python number, a 0-d tensor, a per-sample tensor ``(B,)`` (colours ``(B, 3)``, matrices
``(B, 3, 3)``) or an ``nn.Parameter``, cast to the image's dtype and device and shaped to broadcast against
``(B, 3, H, W)``; their range and choice checks; whether one is a known constant.
"""

from __future__ import annotations

import functools
import numbers
from typing import Union

import torch

from ..runtime.constants import constant, is_plain_number

__all__ = ["Param", "scalar_param", "is_plain_number", "color_param", "matrix_param", "check_range", "check_choice", "is_constant"]

Param = Union[float, int, torch.Tensor]


def _as_tensor(value: Param, image: torch.Tensor, name: str) -> torch.Tensor:
    if isinstance(value, torch.Tensor):
        if value.is_complex() or not (value.is_floating_point() or value.dtype in _INT_DTYPES):
            raise TypeError(f"parameter {name!r} must be a real number tensor, got {value.dtype}")
        return value.to(device=image.device, dtype=image.dtype)
    if not is_plain_number(value):
        raise TypeError(f"parameter {name!r} must be a number or a tensor, got {type(value).__name__}")
    return constant(float(value), image)


_INT_DTYPES = (torch.int8, torch.int16, torch.int32, torch.int64, torch.uint8)


def _per_sample(t: torch.Tensor, image: torch.Tensor, name: str, trailing: int) -> torch.Tensor:
    """Shape a per-sample tensor ``(B, *k)`` to ``(B, *k, 1, 1)`` after checking B against the image."""
    batch = t.shape[0]
    if image.dim() != 4 or image.shape[0] != batch:
        raise ValueError(
            f"parameter {name!r} has {batch} per-sample values but the image has shape {tuple(image.shape)}; "
            f"per-sample parameters need a (B, 3, H, W) image with B = {batch}"
        )
    return t.reshape(t.shape + (1,) * (image.dim() - 1 - trailing))


def scalar_param(value: Param, image: torch.Tensor, name: str) -> torch.Tensor:
    """A scalar control as a tensor that broadcasts against ``image``: 0-d, or ``(B, 1, 1, 1)``.

    Examples:
        >>> image = torch.zeros(2, 3, 4, 4)
        >>> scalar_param(0.5, image, 'gain').shape, scalar_param(torch.tensor([1.0, 2.0]), image, 'gain').shape
        (torch.Size([]), torch.Size([2, 1, 1, 1]))
    """
    t = _as_tensor(value, image, name)
    if t.dim() == 0:
        return t
    if t.dim() == 1:
        return _per_sample(t, image, name, trailing=0)
    raise ValueError(f"parameter {name!r} must be a number, a 0-d tensor or a (B,) tensor, got shape {tuple(t.shape)}")


def color_param(value, image: torch.Tensor, name: str) -> torch.Tensor:
    """An RGB control as ``(3, 1, 1)`` or per sample ``(B, 3, 1, 1)``; accepts a 3-sequence or tensor, or a plain
    number ``v`` for the grey ``(v, v, v)``.

    Examples:
        >>> color_param((1.0, 0.5, 0.25), torch.zeros(1, 3, 2, 2), 'tint').shape
        torch.Size([3, 1, 1])
        >>> color_param(0.5, torch.zeros(1, 3, 2, 2), 'tint').flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    if is_plain_number(value):
        value = (value,) * 3
    t = _as_tensor(value, image, name) if isinstance(value, torch.Tensor) else _sequence(value, image, name)
    if t.shape == (3,):
        return t.reshape(3, 1, 1)
    if t.dim() == 2 and t.shape[1] == 3:
        return _per_sample(t, image, name, trailing=1)
    raise ValueError(f"parameter {name!r} must be an RGB triple (3,) or per-sample (B, 3), got shape {tuple(t.shape)}")


def matrix_param(value, image: torch.Tensor, name: str) -> torch.Tensor:
    """A 3x3 colour matrix as ``(3, 3)`` or per sample ``(B, 3, 3)``.

    Examples:
        >>> matrix_param(((1, 0, 0), (0, 1, 0), (0, 0, 1)), torch.zeros(1, 3, 2, 2), 'mixer').shape
        torch.Size([3, 3])
    """
    t = _as_tensor(value, image, name) if isinstance(value, torch.Tensor) else _sequence(value, image, name)
    if t.shape == (3, 3) or (t.dim() == 3 and t.shape[1:] == (3, 3)):
        if t.dim() == 3:
            _per_sample(t, image, name, trailing=2)
        return t
    raise ValueError(f"parameter {name!r} must be a 3x3 matrix or per-sample (B, 3, 3), got shape {tuple(t.shape)}")


def _sequence(value, image: torch.Tensor, name: str) -> torch.Tensor:
    """A colour or matrix given as (nested) numbers, as a tensor on ``image``'s device, made there once per value."""
    try:
        return constant(_nested_floats(value), image)
    except (TypeError, ValueError, RuntimeError) as error:
        raise TypeError(f"parameter {name!r} must be numbers or a tensor: {error}") from None


def _nested_floats(value):
    """A number or nested sequence of numbers as nested tuples of floats (hashable: a key of the constants' cache)."""
    if isinstance(value, (list, tuple)):
        return tuple(_nested_floats(item) for item in value)
    if not is_plain_number(value):
        raise TypeError(f"expected a number, got {type(value).__name__}")
    return float(value)


def check_range(value: Param, name: str, low: float, high: float) -> None:
    """Raise ``ValueError`` naming ``name`` and its range when a concrete value lies outside [low, high].

    Tensors that require grad are checked too (on detached values); NaN parameters are rejected.

    Examples:
        >>> check_range(150.0, 'contrast', -100.0, 100.0)
        Traceback (most recent call last):
        ...
        ValueError: contrast must lie in [-100.0, 100.0], got 150.0
    """
    t = value.detach() if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float64)
    if t.numel() == 0:
        return
    if torch.isnan(t).any() or (t < low).any() or (t > high).any():
        raise ValueError(f"{name} must lie in [{low}, {high}], got {t.tolist()}")


def check_choice(name: str, value, choices) -> None:
    """Raise ``ValueError`` naming ``name`` and the allowed ``choices`` unless ``value`` is one of them.

    Examples:
        >>> check_choice('metering', 'spot', ('mean', 'log'))
        Traceback (most recent call last):
        ...
        ValueError: metering must be one of 'mean', 'log', got 'spot'
    """
    if value not in tuple(choices):
        raise ValueError(f"{name} must be one of {', '.join(map(repr, choices))}, got {value!r}")


def _flat(value) -> list:
    """A number or nested sequence of numbers as a flat list of its numbers."""
    return [item for part in value for item in _flat(part)] if isinstance(value, (list, tuple)) else [value]


def is_constant(value, constant) -> bool:
    """True when ``value`` is a plain value (a number, or a sequence of numbers) equal to ``constant`` everywhere.

    A tensor never is, nor a sequence holding one: learnable, per-sample or traced, its value may change, and reading
    it back would wait for a device (a stage skips a step of a plain identity value, and computes a tensor's). Plain
    values are compared in Python (a tensor made here would be traced while compiling), a sequence once for each pair
    of values (a stage asks of each of its controls at every call).

    Examples:
        >>> is_constant((0.5, 0.5, 0.5), 0.5), is_constant(torch.tensor(0.5), 0.5), is_constant([[1, 0], [0, 1]], ((1, 0), (0, 1)))
        (True, False, True)
    """
    if _is_number(value):
        if _is_number(constant):
            return value == constant
    elif not isinstance(value, (list, tuple)):
        return False
    try:
        return _equal_everywhere(value, constant)
    except TypeError:  # a list: not hashable, compared as it is
        return _equal_everywhere.__wrapped__(value, constant)


def _is_number(value) -> bool:
    """Whether ``value`` is a real number: a float or an int at once (``numbers.Real``'s check runs Python code)."""
    return isinstance(value, (float, int)) or isinstance(value, numbers.Real)


@functools.lru_cache(maxsize=256)
def _equal_everywhere(value, constant) -> bool:
    """:func:`is_constant` of plain values, one of them a sequence."""
    values, target = _flat(value), _flat(constant)
    if not all(isinstance(item, numbers.Real) for item in (*values, *target)):
        return False
    if len(values) == 1 or len(target) == 1:  # one number against many broadcasts
        return all(v == t for v in values for t in target)
    return values == target
