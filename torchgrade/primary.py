"""Primary grading as OpenColorIO's ``GradingPrimaryTransform`` computes it, and ``PrimaryGrade``.

Two of OpenColorIO's styles, with its controls and units (OCIO 2 ``GradingPrimary``):

* ``"linear"`` (``GRADING_LIN``, scene-linear): ``(rgb + offset) · 2^exposure``, then contrast about
  the pivot ``p = 0.18 · 2^pivot``: ``sign(x) · p · |x / p|^contrast``, then saturation. ``pivot`` is
  in stops above 0.18 and defaults to OpenColorIO's 0.18, so contrast turns about linear 0.2039.
* ``"log"`` (``GRADING_LOG``, log-encoded): ``rgb + brightness · 6.25 / 1023``, then contrast about
  ``a = 0.5 + 0.5 · pivot``: ``(x - a) · contrast + a`` (pivot default -0.2), then gamma between
  ``pivot_black`` and ``pivot_white``: with ``n = (x - black) / (white - black)``,
  ``sign(n) |n|^(1/gamma) · (white - black) + black``, then saturation.

Saturation is ``Y + saturation · (rgb - Y)`` with OpenColorIO's Rec.709 luma weights
``(0.2126, 0.7152, 0.0722)``. Powers are mirrored for negative values, as OpenColorIO does.
OpenColorIO's separate master values fold into the per-channel ones (offsets and exposures add,
contrasts and gammas multiply); its black/white clamps (off by default) are not provided.
"""

from __future__ import annotations

import torch

from .color import CHANNEL, safe_pow
from .core import Param, check_image, check_range, color_param, is_constant, sanitize, scalar_param, to_input_dtype, working_dtype
from .params import ParamModule

STYLES = ("linear", "log")
OCIO_LUMA = (0.2126, 0.7152, 0.0722)
"""OpenColorIO's Rec.709 luma weights (4 digits) for primary saturation."""
DEFAULT_PIVOT = {"linear": 0.18, "log": -0.2}
"""OpenColorIO's default contrast pivot of each style (linear: stops above 0.18; log: ``2a - 1``)."""

# Each control: its identity (or default), allowed range and the styles that have it.
PRIMARY_CONTROLS = {
    "offset": ((0.0, 0.0, 0.0), (-10.0, 10.0), ("linear",)),
    "exposure": ((0.0, 0.0, 0.0), (-20.0, 20.0), ("linear",)),
    "brightness": ((0.0, 0.0, 0.0), (-1023.0, 1023.0), ("log",)),
    "contrast": ((1.0, 1.0, 1.0), (0.0, 10.0), STYLES),
    "gamma": ((1.0, 1.0, 1.0), (0.01, 10.0), ("log",)),
    "saturation": (1.0, (0.0, 10.0), STYLES),
    "pivot": (None, (-10.0, 10.0), STYLES),
    "pivot_black": (0.0, (-1.0, 2.0), ("log",)),
    "pivot_white": (1.0, (-1.0, 2.0), ("log",)),
}
PIVOTS = ("pivot", "pivot_black", "pivot_white")
"""Where contrast and gamma turn: they change nothing by themselves."""


def style_defaults(style: str) -> dict:
    """Every control of ``style`` and its default (``pivot``: :data:`DEFAULT_PIVOT`)."""
    if style not in STYLES:
        raise ValueError(f"style must be one of {STYLES}, got {style!r}")
    return {
        name: DEFAULT_PIVOT[style] if name == "pivot" else default
        for name, (default, _, styles) in PRIMARY_CONTROLS.items()
        if style in styles
    }


def _changed(controls: dict, defaults: dict) -> set:
    """The controls given that change the image (not pivots, not at identity)."""
    return {name for name, value in controls.items() if name not in PIVOTS and not is_constant(value, defaults[name])}


def _mirrored_pow(x: torch.Tensor, exponent: torch.Tensor) -> torch.Tensor:
    """``sign(x) · |x|^exponent`` with finite gradients at 0."""
    return torch.sign(x) * safe_pow(x.abs(), exponent)


def offset_exposure(image: torch.Tensor, offset=(0.0, 0.0, 0.0), exposure=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """OpenColorIO linear offset and exposure: ``(rgb + offset) · 2^exposure``."""
    return (image + color_param(offset, image, "offset")) * torch.exp2(color_param(exposure, image, "exposure"))


def brightness(image: torch.Tensor, amount=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """OpenColorIO log brightness, in 10-bit code values scaled by 6.25: ``rgb + amount · 6.25 / 1023``."""
    return image + color_param(amount, image, "brightness") * (6.25 / 1023.0)


def linear_contrast(image: torch.Tensor, contrast=(1.0, 1.0, 1.0), pivot: Param = 0.18) -> torch.Tensor:
    """OpenColorIO linear contrast: ``sign(x) · p · |x / p|^contrast`` with ``p = 0.18 · 2^pivot``."""
    p = 0.18 * torch.exp2(scalar_param(pivot, image, "pivot"))
    return p * _mirrored_pow(image / p, color_param(contrast, image, "contrast"))


def log_contrast(image: torch.Tensor, contrast=(1.0, 1.0, 1.0), pivot: Param = -0.2) -> torch.Tensor:
    """OpenColorIO log contrast: ``(x - a) · contrast + a`` with ``a = 0.5 + 0.5 · pivot``."""
    a = 0.5 + 0.5 * scalar_param(pivot, image, "pivot")
    return (image - a) * color_param(contrast, image, "contrast") + a


def log_gamma(image: torch.Tensor, gamma=(1.0, 1.0, 1.0), pivot_black: Param = 0.0, pivot_white: Param = 1.0) -> torch.Tensor:
    """OpenColorIO log gamma: ``sign(n) |n|^(1/gamma) · (white - black) + black``, ``n = (x - black) / (white - black)``."""
    black = scalar_param(pivot_black, image, "pivot_black")
    span = scalar_param(pivot_white, image, "pivot_white") - black
    return _mirrored_pow((image - black) / span, 1.0 / color_param(gamma, image, "gamma")) * span + black


def primary_saturation(image: torch.Tensor, amount: Param = 1.0) -> torch.Tensor:
    """OpenColorIO primary saturation: ``Y + amount · (rgb - Y)``, ``Y`` with :data:`OCIO_LUMA`."""
    weights = torch.tensor(OCIO_LUMA, dtype=image.dtype, device=image.device).reshape(3, 1, 1)
    luma = (image * weights).sum(dim=CHANNEL, keepdim=True)
    return luma + (image - luma) * scalar_param(amount, image, "saturation")


def primary_grade(image: torch.Tensor, style: str = "linear", **controls) -> torch.Tensor:
    """OpenColorIO primary grading of ``style`` (see the module docstring); identity returns ``image`` itself.

    Controls: those of :data:`PRIMARY_CONTROLS` that the style has; those not given take
    :func:`style_defaults`.
    """
    check_image(image)
    defaults = style_defaults(style)
    unknown = set(controls) - set(defaults)
    if unknown:
        raise ValueError(f"unknown {style} primary control(s) {sorted(unknown)}; known: {', '.join(defaults)}")
    changed = _changed(controls, defaults)
    if not changed:
        return image
    p = {**defaults, **controls}
    x = sanitize(working_dtype(image))
    if changed & {"offset", "exposure"}:
        x = offset_exposure(x, p["offset"], p["exposure"])
    if "brightness" in changed:
        x = brightness(x, p["brightness"])
    if "contrast" in changed:
        x = (linear_contrast if style == "linear" else log_contrast)(x, p["contrast"], p["pivot"])
    if "gamma" in changed:
        x = log_gamma(x, p["gamma"], p["pivot_black"], p["pivot_white"])
    if "saturation" in changed:
        x = primary_saturation(x, p["saturation"])
    return to_input_dtype(x, image)


class PrimaryGrade(ParamModule):
    """OpenColorIO-style primary grading layer: ``PrimaryGrade(style="linear", offset=(0, 0, 0),
    exposure=(0, 0, 0), contrast=(1, 1, 1), pivot=None, saturation=1.0)``; ``style="log"`` has
    ``brightness``, ``contrast``, ``gamma``, ``pivot``, ``pivot_black``, ``pivot_white``, ``saturation``.

    Colours are triples or per-sample ``(B, 3)``, the others numbers or ``(B,)``; any can be an
    ``nn.Parameter``. ``pivot=None`` takes OpenColorIO's default of the style (0.18, or -0.2 in log).
    Controls of the other style must stay at identity. An identity grade returns its input itself.
    """

    def __init__(self, style: str = "linear", **controls):
        super().__init__()
        defaults = style_defaults(style)
        self.style = style
        for name, value in controls.items():
            if name not in PRIMARY_CONTROLS:
                raise ValueError(f"unknown PrimaryGrade control {name!r}; known: {', '.join(PRIMARY_CONTROLS)}")
            if name not in defaults and not is_constant(value, PRIMARY_CONTROLS[name][0]):
                raise ValueError(f"{name} is not a control of the {style} style; it has {', '.join(defaults)}")
        for name, default in defaults.items():
            value = default if controls.get(name) is None else controls[name]
            check_range(value, name, *PRIMARY_CONTROLS[name][1])
            self.set_param(name, value)

    @property
    def is_identity(self) -> bool:
        """True when no control changes the image (then skipped by ``PostFX`` and not exported)."""
        return not _changed(self.params(), style_defaults(self.style))

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return primary_grade(image, self.style, **self.params())

    def config(self) -> dict:
        """The style and the controls that differ from their defaults, as plain values."""
        defaults = style_defaults(self.style)
        changed = {name: value for name, value in self.plain_params().items() if not is_constant(value, defaults[name])}
        return {"style": self.style, **changed}

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.config().items())
