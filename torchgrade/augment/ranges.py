"""The controls :class:`~torchgrade.RandomPostFX` samples and how its range arguments are read.

A range is ``None`` (off), a ``(min, max)`` pair, or, for a control with an identity (every grading
control), a magnitude ``x >= 0`` meaning ``identity ± x`` as in kornia's colour augmentations
(``contrast=30`` is ``(-30, 30)``, ``split_shadows=0.2`` is ``(0.3, 0.7)``). Unlike kornia, a
magnitude whose range leaves the control's bounds raises instead of being floored.

Examples:
    >>> checked_range("contrast", 30, (-100.0, 100.0), identity=0.0)
    (-30.0, 30.0)
    >>> checked_range("contrast", (-10, 20), (-100.0, 100.0))
    (-10.0, 20.0)
"""

from __future__ import annotations

import math
import numbers

from ..bloom import Bloom
from ..grading.layer import ColorGrade
from ..tonemap import TONEMAP_MODES

__all__ = ["GRADE_CONTROLS", "BLOOM_CONTROLS", "COLOUR_CONTROLS", "INPUT_SPACES", "checked_range", "grade_identity",
           "is_identity_range", "checked_tonemap"]

GRADE_CONTROLS = (
    "post_exposure",
    "temperature",
    "tint",
    "contrast",
    "split_shadows",
    "split_highlights",
    "split_balance",
    "hue_shift",
    "saturation",
)
"""The :func:`torchgrade.grading.grade.color_grade` controls ``RandomPostFX`` samples, in Unity's order."""

COLOUR_CONTROLS = ("split_shadows", "split_highlights")
"""Controls sampled as an RGB colour: each channel drawn independently inside the range."""

BLOOM_CONTROLS = {f"bloom_{name}": (name, Bloom.controls[name].range) for name in ("threshold", "intensity", "scatter")}
"""Bloom controls: the argument of :func:`torchgrade.bloom.bloom` each one sets, and its range (``Bloom``'s own)."""

INPUT_SPACES = ("linear", "srgb")


def _is_number(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, numbers.Real)


def checked_range(name: str, value, allowed: tuple, identity: float | None = None) -> tuple | None:
    """``value`` as a ``(min, max)`` pair of floats, or None; ``ValueError`` naming ``name`` otherwise.

    A number is read as ``identity ± value`` when the control has an ``identity``.

    Examples:
        >>> checked_range("split_shadows", 0.25, (0.0, 1.0), identity=0.5)
        (0.25, 0.75)
        >>> checked_range("hue_shift", -30, (-180.0, 180.0), identity=0.0)
        Traceback (most recent call last):
        ...
        ValueError: hue_shift must be None or a (min, max) pair with min <= max inside [-180.0, 180.0], or a magnitude x >= 0 (the range 0.0 ± x), got -30
    """
    if value is None:
        return None
    low, high = allowed
    message = f"{name} must be None or a (min, max) pair with min <= max inside [{low}, {high}]"
    if identity is not None:
        message += f", or a magnitude x >= 0 (the range {identity} ± x)"
    message += f", got {value!r}"
    if identity is not None and _is_number(value):
        if not value >= 0:
            raise ValueError(message)
        value = (identity - value, identity + value)
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError(message)
    if not all(_is_number(v) for v in value):
        raise ValueError(message)
    pair = (float(value[0]), float(value[1]))
    if not (low <= pair[0] <= pair[1] <= high) or not all(math.isfinite(v) for v in pair):
        raise ValueError(message)
    return pair


def grade_identity(name: str) -> float:
    """The value of grading control ``name`` that changes nothing (a colour's channel value for colours).

    Examples:
        >>> grade_identity("contrast"), grade_identity("split_shadows")
        (0.0, 0.5)
    """
    identity = ColorGrade.controls[name].default
    return float(identity[0] if isinstance(identity, tuple) else identity)


def is_identity_range(name: str, pair: tuple) -> bool:
    """True when a grading range is the single value at which the control changes nothing.

    Examples:
        >>> is_identity_range("saturation", (0.0, 0.0)), is_identity_range("saturation", (0.0, 1.0))
        (True, False)
    """
    return pair[0] == pair[1] == grade_identity(name)


def checked_tonemap(value) -> tuple:
    """``tonemap`` as a tuple of mode names (empty for None).

    Examples:
        >>> checked_tonemap("aces"), checked_tonemap(None)
        (('aces',), ())
    """
    if value is None:
        return ()
    modes = (value,) if isinstance(value, str) else tuple(value)
    if not modes or any(mode not in TONEMAP_MODES for mode in modes):
        raise ValueError(f"tonemap must be None, one of {TONEMAP_MODES} or a non-empty sequence of them, got {value!r}")
    return modes
