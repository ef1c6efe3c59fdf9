"""The look's slots, in the order they run: the one declaration of that order (:data:`SLOTS`), and how a slot's stage is built."""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from torch import nn

from ..base.stage import Stage
from ..bloom import Bloom
from ..exposure import AutoExposure
from ..grading.layer import ColorGrade, PrimaryGrade
from ..lut import LUT3D
from ..output.display import display_settings
from ..output.layer import Display, Dither, LookLUT
from ..tonemap import ToneMap

__all__ = ["Slot", "SLOTS", "SLOT", "STAGES", "stage_keys", "build_stage", "is_identity_stage"]


@dataclass(frozen=True)
class Slot:
    """One place in a look: its ``name`` (the constructor argument, attribute and config key) and ``stage`` class.

    ``shorthand``: the argument a plain string names (``tonemap="aces"`` is ``{"mode": "aces"}``); ``completed``:
    ``(spec, look) -> spec``, arguments completed from the slots before it; ``timed``: the stage keeps state between
    frames and takes ``dt``; ``bakes``: a baked LUT holds it; ``baked``: the slot of the baked LUT itself, which stands
    for the ``bakes`` slots and has no config of its own.
    """

    name: str
    stage: type[Stage]
    shorthand: Optional[str] = None
    completed: Optional[Callable] = None
    timed: bool = False
    bakes: bool = False
    baked: bool = False


SLOTS = (
    Slot("exposure", AutoExposure, timed=True),
    Slot("bloom", Bloom),
    Slot("grade", ColorGrade, bakes=True),
    Slot("primary", PrimaryGrade, bakes=True),
    Slot("tonemap", ToneMap, shorthand="mode", bakes=True),
    Slot("lut", LUT3D, baked=True),
    Slot("look_lut", LookLUT, shorthand="lut"),
    Slot("dither", Dither),
    Slot("display", Display, completed=lambda spec, look: display_settings(spec, look.tonemap)),
)
"""The look's slots, in the order they run: the one declaration of that order. A new slot is one line here."""

SLOT = {slot.name: slot for slot in SLOTS}

STAGES = {slot.name: slot.stage for slot in SLOTS if not slot.baked}
"""The configurable stages, in the order they run, and their classes."""


def stage_keys(stage: str) -> tuple:
    """The argument names a stage's config accepts: its constructor's signature (built from its controls).

    Examples:
        >>> stage_keys("dither")
        ('amplitude', 'seed', 'size')
        >>> stage_keys("primary")[:3]
        ('style', 'offset', 'exposure')
    """
    return tuple(inspect.signature(STAGES[stage]).parameters)


def build_stage(stage: str, spec) -> Optional[nn.Module]:
    """A stage module from a module, a dict of arguments (a slot's shorthand string too) or ``None``.

    Raises ``ValueError`` naming ``stage.key`` for unknown keys and for values the stage rejects.

    Examples:
        >>> build_stage("tonemap", "aces")
        ToneMap(mode='aces')
        >>> build_stage("grade", {"contrast": 150})
        Traceback (most recent call last):
        ...
        ValueError: grade.contrast must lie in [-100.0, 100.0], got 150.0
    """
    if spec is None or isinstance(spec, nn.Module):
        return spec
    shorthand = SLOT[stage].shorthand
    if shorthand and isinstance(spec, (str, Path)):
        spec = {shorthand: spec}
    if not isinstance(spec, dict):
        raise ValueError(f"{stage} must be a module, a dict of its arguments or None, got {type(spec).__name__}")
    known = stage_keys(stage)
    for key in spec:
        if key not in known:
            raise ValueError(f"unknown key '{stage}.{key}'; {stage} takes {', '.join(known)}")
    try:
        return STAGES[stage].from_config(spec)
    except (ValueError, TypeError, OSError) as error:
        raise ValueError(_qualified(stage, str(error), spec)) from None


def _qualified(stage: str, message: str, spec: dict) -> str:
    """Prefix a stage's error with ``stage.`` when it starts with one of the given keys, else ``stage: ``."""
    named = any(message.startswith(f"{key} ") for key in spec)
    return f"{stage}.{message}" if named else f"{stage}: {message}"


def is_identity_stage(module: nn.Module) -> bool:
    """True for a stage that cannot change any image, as the stage itself says (``is_identity``).

    Examples:
        >>> is_identity_stage(ColorGrade()), is_identity_stage(Dither(amplitude=0.0)), is_identity_stage(AutoExposure())
        (True, True, False)
    """
    return bool(getattr(module, "is_identity", False))
