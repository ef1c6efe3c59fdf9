"""A stage's controls: the :class:`Control` each table holds (default, range, kind), how a value is checked against it,
and what the other doors make of a table (a constructor's signature, the functional API's checks, plain values for a
config).

Examples:
    >>> Control(0.0, (-100.0, 100.0)).check("contrast", 20.0)
    20.0
"""

from __future__ import annotations

import inspect
import numbers
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from .params import check_choice, check_range, is_plain_number

__all__ = ["KINDS", "Control", "plain", "in_state_check", "check_given", "refuse_unknown", "controls_signature", "digit_count"]


KINDS = ("number", "int", "bool", "choice", "value")


@dataclass(frozen=True)
class Control:
    """One control of a stage: its ``default`` (identity where the stage has one) and its ``range``.

    ``kind`` says how values are checked:

    * ``"number"``: a number, a sequence of numbers (colours, matrices) or a tensor, every element
      in ``range = (low, high)``; may be a per-sample tensor or an ``nn.Parameter``. A number
      control whose default is ``None`` (not set) also accepts ``None``; a colour (a default of three
      numbers) also accepts one number ``v``, kept as the grey ``(v, v, v)``.
    * ``"int"``: a Python ``int`` (not ``bool``) in ``range``.
    * ``"bool"``: ``True`` or ``False``.
    * ``"choice"``: one of the strings in ``range``.
    * ``"value"``: checked by the stage itself (:meth:`Stage.check_control`): textures, curves.

    Examples:
        >>> Control(0.0, (-100.0, 100.0)).kind
        'number'
        >>> Control("log", ("mean", "log")).kind
        'choice'
    """

    default: Any
    range: Any = None
    kind: str = ""

    def __post_init__(self):
        if not self.kind:
            object.__setattr__(self, "kind", _inferred_kind(self.default, self.range))
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")

    def check(self, name: str, value):
        """``value`` checked against this control's kind and range (an ``"int"`` returned as ``int``), or ``ValueError`` naming ``name``.

        A ``"value"`` control is returned unchecked: its stage checks it (:meth:`Stage.check_control`).

        Examples:
            >>> Control((1.0, 1.0, 1.0), (0.0, 10.0)).check("tint", 0.5)
            (0.5, 0.5, 0.5)
            >>> Control(16, (0, 16)).check("max_iterations", 17)
            Traceback (most recent call last):
            ...
            ValueError: max_iterations must be an integer in [0, 16], got 17
            >>> Control(0.0, (-100.0, 100.0)).check("contrast", [10.0, 20.0])
            [10.0, 20.0]
        """
        if self.kind == "number":
            # A number control that defaults to None ("not set", as a speed that falls back on another) keeps None.
            if not (value is None and self.default is None):
                value = _as_grey(value, self.default)
                _check_number(value, name, self.range)
                _check_shape(value, name, self.default)
        elif self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not self.range[0] <= value <= self.range[1]:
                shown = f"one of {digit_count(value)} digits" if digit_count(value) > 30 else repr(value)
                raise ValueError(f"{name} must be an integer in [{self.range[0]}, {self.range[1]}], got {shown}")
            value = int(value)
        elif self.kind == "bool":
            if not isinstance(value, bool):
                raise ValueError(f"{name} must be True or False, got {value!r}")
        elif self.kind == "choice":
            check_choice(name, value, self.range)
        return value


def _inferred_kind(default, allowed) -> str:
    if isinstance(default, bool):
        return "bool"
    if isinstance(default, str):
        return "choice"
    if isinstance(default, int) and allowed is not None:
        return "int"
    return "number" if allowed is not None else "value"


def plain(value):
    """A stored control as a plain, JSON-ready value: tensors as numbers or nested lists, tuples as lists.

    Examples:
        >>> plain(torch.tensor([1.0, 2.0]))
        [1.0, 2.0]
        >>> plain(((1.0, 0.0), (0.0, 1.0)))
        [[1.0, 0.0], [0.0, 1.0]]
    """
    if isinstance(value, torch.Tensor):
        return value.detach().cpu().tolist()
    if isinstance(value, (tuple, list)):
        return [plain(v) for v in value]
    return value


def in_state_check(value) -> bool:
    """True for a stored value :meth:`Stage.check_state` checks: not a learnable ``nn.Parameter`` (checked at every
    forward instead, :meth:`Stage.check_learnable`) and not a tensor on ``meta`` (which holds no values).

    Examples:
        >>> in_state_check(torch.tensor(2.0)), in_state_check(nn.Parameter(torch.tensor(2.0)))
        (True, False)
        >>> in_state_check(torch.empty(3, device="meta")), in_state_check(0.5)
        (False, True)
    """
    return not isinstance(value, nn.Parameter) and not (isinstance(value, torch.Tensor) and value.is_meta)


def check_given(table: dict, params: dict, owner: str) -> None:
    """Check the controls of ``params`` given as plain values (numbers, integers, triples, lists of them) against ``table``, a
    stage's :class:`Control` table, with its ranges and messages: the functional API's door, where a stage checks at
    construction. Tensors are not read (on a GPU each read would wait for the device; a stage checks its learnable
    values with :meth:`Stage.check_learnable`). A name outside the table is refused as the stage ``owner`` refuses it
    (:func:`refuse_unknown`).

    Examples:
        >>> table = {"contrast": Control(0.0, (-100.0, 100.0))}
        >>> check_given(table, {"contrast": 500.0}, "ColorGrade")
        Traceback (most recent call last):
        ...
        ValueError: contrast must lie in [-100.0, 100.0], got 500.0
        >>> check_given(table, {"contrast": torch.tensor(500.0)}, "ColorGrade")  # not read
        >>> check_given(table, {"brightness": 1.0}, "ColorGrade")
        Traceback (most recent call last):
        ...
        ValueError: unknown ColorGrade control(s) ['brightness']; known: contrast
    """
    refuse_unknown(table, params, owner)
    for name, value in params.items():
        control = table.get(name)
        if control is not None and control.kind in ("number", "int") and not _holds_tensor(value):
            control.check(name, value)


def refuse_unknown(table: dict, names, owner: str) -> None:
    """Raise ``ValueError`` naming the ``names`` that ``table`` lacks, ``owner``'s controls, and the known ones.

    Examples:
        >>> refuse_unknown({"amplitude": Control(0.0, (0.0, 1.0))}, ["amplitude", "nan_free"], "Dither")
        Traceback (most recent call last):
        ...
        ValueError: unknown Dither control(s) ['nan_free']; known: amplitude
    """
    unknown = [name for name in names if name not in table]
    if unknown:
        raise ValueError(f"unknown {owner} control(s) {sorted(unknown)}; known: {', '.join(table) or 'none'}")


def _holds_tensor(value) -> bool:
    if isinstance(value, (tuple, list)):
        return any(_holds_tensor(v) for v in value)
    return isinstance(value, torch.Tensor)


def controls_signature(controls: dict, leading: tuple = ()) -> inspect.Signature:
    """A constructor signature listing ``leading`` parameters, then every control as a keyword with its default.

    Stages that take ``**controls`` set it as ``__signature__`` so ``help()`` and IDEs show the names.

    Examples:
        >>> str(controls_signature({"contrast": Control(0.0, (-100.0, 100.0))}))
        '(*, contrast=0.0)'
    """
    keyword = inspect.Parameter.KEYWORD_ONLY
    parameters = list(leading)
    parameters += [inspect.Parameter(name, keyword, default=control.default) for name, control in controls.items()]
    return inspect.Signature(parameters)


def _check_number(value, name: str, allowed) -> None:
    if isinstance(value, bool) or isinstance(value, str):
        raise ValueError(f"{name} must be a number or a tensor, got {value!r}")
    if isinstance(value, torch.Tensor) and (value.is_complex() or value.dtype == torch.bool):
        raise ValueError(f"{name} must be a real number tensor, got {value.dtype}")
    try:
        check_range(value, name, *allowed)
    except (TypeError, RuntimeError) as error:
        raise ValueError(f"{name} must be numbers or a tensor: {error}") from None


def _as_grey(value, default):
    """``value``, or the grey ``(v, v, v)`` where ``value`` is a plain number ``v`` and ``default`` a colour (three numbers)."""
    colour = isinstance(default, (tuple, list)) and len(default) == 3 and all(isinstance(v, numbers.Real) for v in default)
    is_number = is_plain_number(value)
    return (value,) * 3 if colour and is_number else value


def _check_shape(value, name: str, default) -> None:
    """Raise ``ValueError`` unless ``value`` has its control's shape (that of ``default``: a number, a colour ``(3,)``, a
    trackball ``(4,)``, a matrix ``(3, 3)``) or is a batch of such ``(B, ...)``: a lift of two numbers or a 2x2 mixer was
    taken and refused only at the first frame."""
    shape = tuple(torch.as_tensor(default if default is not None else 0.0, dtype=torch.float64).shape)
    given = tuple(value.shape) if isinstance(value, torch.Tensor) else tuple(torch.as_tensor(value, dtype=torch.float64).shape)
    if given != shape and given[1:] != shape:
        expected = "a number or a (B,) tensor" if not shape else f"of shape {shape} or (B, {', '.join(map(str, shape))})"
        raise ValueError(f"{name} must be {expected}, got shape {given}")


def digit_count(value) -> int:
    """The most digits of any integer in ``value`` (a number or nested sequence), for an overflow's message."""
    if isinstance(value, (list, tuple)):
        return max((digit_count(item) for item in value), default=0)
    return len(str(abs(value))) if isinstance(value, int) else 0
