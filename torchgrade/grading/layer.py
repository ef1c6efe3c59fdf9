"""The grading stages: ``ColorGrade`` (Unity's controls in Unity's order) and ``PrimaryGrade`` (OpenColorIO's primary grading)."""

from __future__ import annotations

import inspect

import torch

from ..base.params import Param, is_constant
from ..base.controls import controls_signature
from ..base.stage import Stage
from ..runtime.strips import pixelwise
from .curves import CurveControl, check_curve, stored_curve
from .grade import (
    COLOR_GRADE_CONTROLS,
    GRADE_SETTINGS,
    active_steps,
    graded_image,
    is_identity_control,
)
from .primary import (
    PIVOTS,
    PRIMARY_GRADE_CONTROLS,
    check_pivots,
    primary_graded,
    style_table,
)

__all__ = ["ColorGrade", "PrimaryGrade", "check_zone"]


def check_zone(start: Param, end: Param, zone: str) -> None:
    """A tonal zone's start below its end, as :class:`ColorGrade` orders ``shadows_*`` and ``highlights_*``.

    Examples:
        >>> check_zone(0.5, 0.25, "shadows")
        Traceback (most recent call last):
        ...
        ValueError: shadows_start must be below shadows_end, got 0.5 and 0.25
    """
    start_t, end_t = torch.as_tensor(start).detach(), torch.as_tensor(end).detach()
    if start_t.is_meta or end_t.is_meta:  # no values to compare
        return
    if (start_t >= end_t).any():
        raise ValueError(f"{zone}_start must be below {zone}_end, got {start_t.tolist()} and {end_t.tolist()}")


class ColorGrade(Stage):
    """Colour grading layer with Unity's controls (see the module docstring for order and units).

    Every control accepts a number (colour: a triple; trackball: ``(r, g, b, w)``; mixer: a 3x3
    nested sequence), a tensor, a per-sample tensor ``(B,)``/``(B, 3)``/``(B, 4)``/``(B, 3, 3)``, or
    an ``nn.Parameter`` to learn it. Curves (the table's :class:`~torchgrade.grading.curves.CurveControl`
    entries) take control points ``((x, y), ...)`` or an ``(N, 2)`` tensor, shared by the batch.
    Controls left at identity cost nothing; an all-identity grade returns its input unchanged.

    Examples:
        >>> import torch
        >>> grade = ColorGrade(contrast=20, saturation=-100)
        >>> out = grade(torch.rand(1, 3, 4, 4))
        >>> bool(torch.allclose(out[:, 0], out[:, 1], atol=1e-5))  # saturation -100: grey
        True
        >>> ColorGrade().is_identity
        True
    """

    per_pixel = True

    # Each control, its identity value and its allowed range, in Unity's order; then the curves.
    controls = COLOR_GRADE_CONTROLS
    aces: bool
    log_space: str
    shadows_start: Param
    shadows_end: Param
    highlights_start: Param
    highlights_end: Param

    def __init__(self, aces: bool = False, **controls):
        super().__init__()
        self.init_controls(aces=bool(aces), **controls)

    def check_control(self, name: str, value):
        control = self.controls[name]
        if isinstance(control, CurveControl):
            check_curve(name, value, control.periodic)
            return stored_curve(value)
        return value

    def check_together(self) -> None:
        if self.log_space != "acescc" and not self.aces:
            raise ValueError(f"log_space {self.log_space!r} grades contrast in ACES: it needs aces=True")
        check_zone(self.shadows_start, self.shadows_end, "shadows")
        check_zone(self.highlights_start, self.highlights_end, "highlights")

    def is_default(self, name: str) -> bool:
        if name in GRADE_SETTINGS:
            return super().is_default(name)
        return is_identity_control(name, getattr(self, name))

    @property
    def is_identity(self) -> bool:
        """True when no control changes the image (the layer is then skipped and not exported)."""
        return not active_steps(self.params())

    def curves(self) -> dict:
        """The curves that change something, by name (as stored)."""
        curves = (name for name, control in self.controls.items() if isinstance(control, CurveControl))
        return {name: getattr(self, name) for name in curves if not self.is_default(name)}

    @pixelwise(planes=True)
    def forward(self, image: torch.Tensor, *, nan_free: bool = False, planes: bool = False) -> torch.Tensor:
        return graded_image(image, nan_free=nan_free, planes=planes, **self.params())


ColorGrade.__signature__ = controls_signature(ColorGrade.controls)


class PrimaryGrade(Stage):
    """OpenColorIO-style primary grading layer: ``PrimaryGrade(style="linear", offset=(0, 0, 0),
    exposure=(0, 0, 0), contrast=(1, 1, 1), pivot=None, saturation=1.0)``; ``style="log"`` has
    ``brightness``, ``contrast``, ``gamma``, ``pivot``, ``pivot_black``, ``pivot_white``, ``saturation``.

    Colours are triples or per-sample ``(B, 3)``, the others numbers or ``(B,)``; any can be an
    ``nn.Parameter``. ``pivot=None`` (or any control ``None``) takes OpenColorIO's default of the
    style (pivot 0.18, or -0.2 in log). Controls of the other style must stay at identity. The style
    is set at construction. An identity grade returns its input itself.

    Examples:
        >>> grade = PrimaryGrade("log", contrast=(1.2, 1.2, 1.2))
        >>> grade.to_config()
        {'style': 'log', 'contrast': [1.2, 1.2, 1.2]}
        >>> PrimaryGrade(gamma=(2.0, 1.0, 1.0))
        Traceback (most recent call last):
        ...
        ValueError: gamma is not a control of the linear style; it has offset, exposure, contrast, saturation, pivot
    """

    per_pixel = True

    # Each control, its identity (or default) and its allowed range; STYLE_CONTROLS says which style has it.
    controls = PRIMARY_GRADE_CONTROLS
    always_in_config = ("style",)
    style: str
    pivot_black: Param
    pivot_white: Param

    def __init__(self, style: str = "linear", **controls):
        super().__init__()
        object.__setattr__(self, "style", style)  # the table depends on it: see control_table
        table = self.control_table()
        given = {name: value for name, value in controls.items() if value is not None}
        for name, value in list(given.items()):
            if name in self.controls and name not in table and is_constant(value, self.controls[name].default):
                del given[name]
            elif name in self.controls and name not in table:
                raise ValueError(f"{name} is not a control of the {style} style; it has {', '.join(list(table)[1:])}")
        self.init_controls(style=style, **given)

    def control_table(self) -> dict:
        """The style's controls, ``pivot`` defaulting to the style's own (:data:`DEFAULT_PIVOT`)."""
        return {"style": self.controls["style"], **style_table(self.style)}

    def check_control(self, name: str, value):
        if name == "style" and value != self.style:
            raise ValueError(f"a PrimaryGrade's style is set at construction; build a new one for {value!r}")
        return value

    def check_together(self) -> None:
        if self.style == "log":
            check_pivots(self.pivot_black, self.pivot_white)

    @property
    def is_identity(self) -> bool:
        """True when no control changes the image (then skipped by ``PostFX`` and not exported)."""
        return all(self.is_default(name) for name in self._control_names if name not in ("style", *PIVOTS))

    @pixelwise
    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        return primary_graded(image, nan_free=nan_free, **self.params())


PrimaryGrade.__signature__ = controls_signature(
    {name: control for name, control in PrimaryGrade.controls.items() if name != "style"},
    leading=(inspect.Parameter("style", inspect.Parameter.POSITIONAL_OR_KEYWORD, default="linear"),),
)
