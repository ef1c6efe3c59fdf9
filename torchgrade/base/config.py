"""Look configs from untrusted JSON: bounded reading and the JSON types each control accepts.

A config file is read only when it is a regular file of at most :data:`MAX_CONFIG_BYTES`, and parsed
only when its nesting is at most :data:`MAX_CONFIG_DEPTH` (Python's ``json`` recurses once per level,
so 100,000 nested brackets would raise ``RecursionError``). ``NaN`` and ``Infinity``, which Python's
``json`` accepts but JSON does not, are refused.

:func:`config_value` checks a stage argument against its control's kind before the stage sees it, and
turns a nested list back into the per-sample tensor that :meth:`~torchgrade.base.stage.Stage.to_config`
wrote as a list (a list nested deeper than the control's default, as ``[10, 20]`` for a contrast).
"""

from __future__ import annotations

import json

import numpy as np
import torch

from .controls import Control
from .files import read_regular


__all__ = ["load_config", "config_value", "MAX_CONFIG_BYTES", "MAX_CONFIG_DEPTH"]

MAX_CONFIG_BYTES = 16 << 20
"""Largest config file read: a look is a few kilobytes; 16 MiB leaves room for long per-sample lists."""

MAX_CONFIG_DEPTH = 32
"""Deepest nesting of arrays and objects: a look needs 4 (stage, control, sample, matrix row)."""



def load_config(path) -> dict:
    """The JSON object in file ``path``, or ``ValueError`` naming what makes it unfit to read.

    Examples:
        >>> load_config("/dev/zero")
        Traceback (most recent call last):
        ...
        ValueError: config /dev/zero is not a regular file
    """
    data = read_regular(path, MAX_CONFIG_BYTES, "config")
    depth = json_depth(data)
    if depth > MAX_CONFIG_DEPTH:
        raise ValueError(f"config {path} nests {depth} levels deep; at most {MAX_CONFIG_DEPTH}")
    try:
        config = json.loads(data, parse_constant=_refuse_constant)
    except ValueError as error:  # JSONDecodeError and UnicodeDecodeError
        raise ValueError(f"config {path} is not valid JSON: {error}") from None
    if not isinstance(config, dict):
        raise ValueError(f"config {path} must hold a JSON object, got {type(config).__name__}")
    return config


def json_depth(data: bytes) -> int:
    r"""The deepest nesting of ``[`` and ``{`` in JSON text, strings skipped, without recursing, in time linear in
    the text: a quote opens or closes a string unless an odd run of backslashes comes just before it.

    Examples:
        >>> json_depth(rb'{"a": [[1], "]]]\"[["]}')
        3
    """
    text = np.frombuffer(data, dtype=np.uint8)
    quotes = np.flatnonzero(text == ord('"'))
    others = np.flatnonzero(text != ord("\\"))  # the bytes that are not backslashes (every quote among them)
    before = np.searchsorted(others, quotes)  # how many of them come before each quote
    last_other = np.where(before > 0, others[np.maximum(before - 1, 0)], -1)
    escaped = (quotes - 1 - last_other) % 2 == 1
    quotes = quotes[~escaped]
    opening = np.flatnonzero((text == ord("[")) | (text == ord("{")))
    closing = np.flatnonzero((text == ord("]")) | (text == ord("}")))
    brackets = np.concatenate((opening, closing))
    steps = np.concatenate((np.ones(opening.size, np.int64), -np.ones(closing.size, np.int64)))
    outside = np.searchsorted(quotes, brackets) % 2 == 0  # an even number of quotes before: not in a string
    order = np.argsort(brackets[outside], kind="stable")
    return int(np.cumsum(steps[outside][order]).max(initial=0))


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def config_value(name: str, value, control: Control):
    """``value`` checked against the JSON types ``control``'s kind takes; a per-sample list as a tensor.

    Values that are not JSON types (tensors, parameters) are left to the stage's own checks.

    Examples:
        >>> from torchgrade.base.controls import Control
        >>> config_value("contrast", [10, 20], Control(0.0, (-100.0, 100.0)))
        tensor([10., 20.])
        >>> config_value("aces", 1, Control(False))
        Traceback (most recent call last):
        ...
        ValueError: aces must be true or false, got 1
    """
    if control.kind == "bool" and not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    if control.kind == "choice" and not isinstance(value, str):
        raise ValueError(f"{name} must be one of {', '.join(map(repr, control.range))}, got {value!r}")
    if control.kind == "number" and isinstance(value, list):
        samples = _number_array(name, value)
        if samples.dim() > _depth(control.default):
            return samples
    return value


def _number_array(name: str, value: list) -> torch.Tensor:
    """A non-empty, rectangular nested list of numbers (not booleans) as a float tensor."""
    flat = value
    while flat and all(isinstance(item, list) for item in flat):
        flat = [number for item in flat for number in item]
    if not flat or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in flat):
        raise ValueError(f"{name} must be a number or a non-empty (nested) list of numbers, got {str(value)[:80]}")
    try:
        return torch.tensor(value, dtype=torch.get_default_dtype())
    except OverflowError:  # integers beyond float range
        raise ValueError(f"{name} must be numbers a float can hold") from None
    except (TypeError, ValueError, RuntimeError) as error:  # ragged lists
        raise ValueError(f"{name} must be a rectangular list of numbers: {error}") from None


def _depth(default) -> int:
    """How deeply a control's plain value nests: 0 for a number, 1 for a colour, 2 for a matrix."""
    return 1 + _depth(default[0]) if isinstance(default, (tuple, list)) and default else 0
