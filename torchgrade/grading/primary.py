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

from ..base.images import check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import Param, check_choice, color_param, is_constant, is_plain_number, scalar_param
from ..base.planes import bounded_pow
from ..base.controls import Control, check_given, refuse_unknown
from ..color import CHANNEL
from ..runtime import constant

__all__ = [
    "primary_grade",
    "primary_graded",
    "style_defaults",
    "offset_exposure",
    "brightness",
    "linear_contrast",
    "primary_log_contrast",
    "log_gamma",
    "primary_saturation",
    "STYLE_CONTROLS",
    "DEFAULT_PIVOT",
    "OCIO_LUMA",
]

STYLE_CONTROLS = {
    "linear": ("offset", "exposure", "contrast", "saturation", "pivot"),
    "log": ("brightness", "contrast", "gamma", "saturation", "pivot", "pivot_black", "pivot_white"),
}
"""The controls each of OpenColorIO's styles has."""
STYLES = tuple(STYLE_CONTROLS)
OCIO_LUMA = (0.2126, 0.7152, 0.0722)
"""OpenColorIO's Rec.709 luma weights (4 digits) for primary saturation."""
DEFAULT_PIVOT = {"linear": 0.18, "log": -0.2}
"""OpenColorIO's default contrast pivot of each style (linear: stops above 0.18; log: ``2a - 1``)."""
PIVOTS = ("pivot", "pivot_black", "pivot_white")
"""Where contrast and gamma turn: they change nothing by themselves."""


PRIMARY_GRADE_CONTROLS = {
    "style": Control("linear", STYLES),
    "offset": Control((0.0, 0.0, 0.0), (-10.0, 10.0)),
    "exposure": Control((0.0, 0.0, 0.0), (-20.0, 20.0)),
    "brightness": Control((0.0, 0.0, 0.0), (-1023.0, 1023.0)),
    "contrast": Control((1.0, 1.0, 1.0), (0.0, 10.0)),
    "gamma": Control((1.0, 1.0, 1.0), (0.01, 10.0)),
    "saturation": Control(1.0, (0.0, 10.0)),
    "pivot": Control(None, (-10.0, 10.0)),
    "pivot_black": Control(0.0, (-1.0, 2.0)),
    "pivot_white": Control(1.0, (-1.0, 2.0)),
}
""":class:`~torchgrade.PrimaryGrade`'s controls, ``{name: Control}``: every style's, the pivots included."""


MIN_PIVOT_SPAN = 1e-3
"""Least ``pivot_white - pivot_black``. OpenColorIO asks only that black lie below white (``GradingPrimary::validate``);
the gamma divides by the span, and at a span of 6.7e-22 its gradient with respect to the pivots overflowed float32.
A thousandth of a log code is far below any visible gamma range."""


def check_pivots(black: Param, white: Param) -> None:
    """OpenColorIO's rule, with a least span: ``pivot_white - pivot_black >= MIN_PIVOT_SPAN``."""
    message = f"pivot_black must be below pivot_white by at least {MIN_PIVOT_SPAN}"
    if not isinstance(black, torch.Tensor) and not isinstance(white, torch.Tensor):
        if not white - black >= MIN_PIVOT_SPAN:
            raise ValueError(f"{message}, got {black} and {white}")
        return
    black_t, white_t = (torch.as_tensor(v, dtype=torch.float64).detach() for v in (black, white))
    if black_t.is_meta or white_t.is_meta:  # no values to compare
        return
    if not bool((white_t - black_t >= MIN_PIVOT_SPAN).all()):
        raise ValueError(f"{message}, got {black_t.tolist()} and {white_t.tolist()}")


def style_defaults(style: str) -> dict:
    """Every control of ``style`` and its default (``pivot``: :data:`DEFAULT_PIVOT`).

    Examples:
        >>> style_defaults("log")["pivot"], list(style_defaults("linear"))
        (-0.2, ['offset', 'exposure', 'contrast', 'saturation', 'pivot'])
    """
    return {name: control.default for name, control in style_table(style).items()}


def style_table(style: str) -> dict:
    """The controls of ``style`` in :attr:`PRIMARY_GRADE_CONTROLS` order, ``pivot`` defaulting to the style's."""
    check_choice("style", style, STYLES)
    table = {}
    for name, control in PRIMARY_GRADE_CONTROLS.items():
        if name in STYLE_CONTROLS[style]:
            table[name] = Control(DEFAULT_PIVOT[style], control.range) if name == "pivot" else control
    return table


def _changed(controls: dict, defaults: dict) -> set:
    """The controls given that change the image (not pivots, not at identity)."""
    return {name for name, value in controls.items() if name not in PIVOTS and not is_constant(value, defaults[name])}


def _mirrored_pow(x: torch.Tensor, exponent: torch.Tensor) -> torch.Tensor:
    """``sign(x) · |x|^exponent`` with finite gradients at 0, saturating at ±65504 instead of overflowing.

    OpenColorIO's own limits (contrast up to 10, gamma down to 0.01: a power of 100) overflow float32
    on HDR values; saturating keeps every documented control value finite (``bounded_pow``).
    """
    return torch.sign(x) * bounded_pow(x.abs(), exponent)


def offset_exposure(image: torch.Tensor, offset=(0.0, 0.0, 0.0), exposure=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """OpenColorIO linear offset and exposure: ``(rgb + offset) · 2^exposure``.

    Examples:
        >>> offset_exposure(torch.full((3, 1, 1), 0.25), offset=(0.25, 0.25, 0.25), exposure=(1.0, 0.0, 0.0)).flatten().tolist()
        [1.0, 0.5, 0.5]
    """
    return (image + color_param(offset, image, "offset")) * torch.exp2(color_param(exposure, image, "exposure"))


def brightness(image: torch.Tensor, amount=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """OpenColorIO log brightness, in 10-bit code values scaled by 6.25: ``rgb + amount · 6.25 / 1023``.

    Examples:
        >>> round(brightness(torch.zeros(3, 1, 1), (1023.0, 0.0, 0.0)).flatten()[0].item(), 4)
        6.25
    """
    return image + color_param(amount, image, "brightness") * (6.25 / 1023.0)


def linear_contrast(image: torch.Tensor, contrast=(1.0, 1.0, 1.0), pivot: Param = 0.18) -> torch.Tensor:
    """OpenColorIO linear contrast: ``sign(x) · p · |x / p|^contrast`` with ``p = 0.18 · 2^pivot``.

    Examples:
        >>> linear_contrast(torch.full((3, 1, 1), 0.18), (2.0, 2.0, 2.0), pivot=0.0).flatten().tolist()  # the pivot stays
        [0.18000000715255737, 0.18000000715255737, 0.18000000715255737]
    """
    p = 0.18 * torch.exp2(scalar_param(pivot, image, "pivot"))
    return p * _mirrored_pow(image / p, color_param(contrast, image, "contrast"))


def primary_log_contrast(image: torch.Tensor, contrast=(1.0, 1.0, 1.0), pivot: Param = -0.2) -> torch.Tensor:
    """OpenColorIO log contrast: ``(x - a) · contrast + a`` with ``a = 0.5 + 0.5 · pivot``.

    Examples:
        >>> primary_log_contrast(torch.full((3, 1, 1), 0.4), (2.0, 2.0, 2.0)).flatten().tolist()  # pivot -0.2: a = 0.4 stays
        [0.4000000059604645, 0.4000000059604645, 0.4000000059604645]
    """
    a = 0.5 + 0.5 * scalar_param(pivot, image, "pivot")
    return (image - a) * color_param(contrast, image, "contrast") + a


def log_gamma(image: torch.Tensor, gamma=(1.0, 1.0, 1.0), pivot_black: Param = 0.0, pivot_white: Param = 1.0) -> torch.Tensor:
    """OpenColorIO log gamma: ``sign(n) |n|^(1/gamma) · (white - black) + black``, ``n = (x - black) / (white - black)``.

    Examples:
        >>> log_gamma(torch.full((3, 1, 1), 0.25), (0.5, 0.5, 0.5)).flatten().tolist()  # n^(1/0.5)
        [0.0625, 0.0625, 0.0625]
    """
    black = scalar_param(pivot_black, image, "pivot_black")
    span = scalar_param(pivot_white, image, "pivot_white") - black
    return _mirrored_pow((image - black) / span, 1.0 / color_param(gamma, image, "gamma")) * span + black


def primary_saturation(image: torch.Tensor, amount: Param = 1.0) -> torch.Tensor:
    """OpenColorIO primary saturation: ``Y + amount · (rgb - Y)``, ``Y`` with :data:`OCIO_LUMA`.

    Examples:
        >>> primary_saturation(torch.tensor([1.0, 0.0, 0.0]).reshape(3, 1, 1), 0.0).flatten().tolist()
        [0.2125999927520752, 0.2125999927520752, 0.2125999927520752]
    """
    weights = constant(OCIO_LUMA, image).reshape(3, 1, 1)
    luma = (image * weights).sum(dim=CHANNEL, keepdim=True)
    return luma + (image - luma) * scalar_param(amount, image, "saturation")


def primary_grade(image: torch.Tensor, style: str = "linear", **controls) -> torch.Tensor:
    """OpenColorIO primary grading of ``style`` (see the module docstring); identity returns ``image`` itself.

    Controls: those of :attr:`PRIMARY_GRADE_CONTROLS` that the style has (:data:`STYLE_CONTROLS`);
    those not given take :func:`style_defaults`. Controls given as numbers are checked as
    :class:`~torchgrade.PrimaryGrade` checks them (:func:`style_table`); tensors are taken as they are.

    Examples:
        >>> image = torch.full((1, 3, 1, 1), 0.5)
        >>> primary_grade(image, "linear", exposure=(1.0, 1.0, 1.0)).flatten().tolist()
        [1.0, 1.0, 1.0]
        >>> primary_grade(image, "log", pivot=0.3) is image  # a pivot alone changes nothing
        True
        >>> primary_grade(image, saturation=50.0)
        Traceback (most recent call last):
        ...
        ValueError: saturation must lie in [0.0, 10.0], got 50.0
    """
    check_given(style_table(style), controls, f"{style} PrimaryGrade")
    return primary_graded(image, style, **controls)


def primary_graded(image: torch.Tensor, style: str = "linear", *, nan_free: bool = False, **controls) -> torch.Tensor:
    """:func:`primary_grade` without checking the controls' values: for :class:`~torchgrade.PrimaryGrade`, which
    checked them when they were set, on every strip of a frame. ``nan_free``: ``image`` holds no NaN
    (:func:`~torchgrade.base.images.sanitize`).

    Examples:
        >>> image = torch.rand(1, 3, 2, 2)
        >>> torch.equal(primary_graded(image, saturation=1.5), primary_grade(image, saturation=1.5))
        True
    """
    check_image(image)
    defaults = style_defaults(style)
    refuse_unknown(defaults, controls, f"{style} PrimaryGrade")
    changed = _changed(controls, defaults)
    if not changed:
        return image
    p = {**defaults, **controls}
    x = sanitize(working_dtype(image), nan_free=nan_free)
    if changed & {"offset", "exposure"}:
        x = offset_exposure(x, p["offset"], p["exposure"])
    if "brightness" in changed:
        x = brightness(x, p["brightness"])
    if "contrast" in changed:
        x = (linear_contrast if style == "linear" else primary_log_contrast)(x, p["contrast"], p["pivot"])
    if "gamma" in changed:
        if is_plain_number(p["pivot_black"]) and is_plain_number(p["pivot_white"]):  # a stage checks tensors when set
            check_pivots(p["pivot_black"], p["pivot_white"])
        x = log_gamma(x, p["gamma"], p["pivot_black"], p["pivot_white"])
    if "saturation" in changed:
        x = primary_saturation(x, p["saturation"])
    return to_input_dtype(x, image)
