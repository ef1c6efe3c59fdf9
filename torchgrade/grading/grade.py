"""Colour grading in Unity URP/HDRP's order, with Unity's controls and units.

Order (Catlike Coding, Color Grading §1-2, matching Unity's ``ColorGrade``; the lift/gamma/gain
and curve steps where URP's LUT builder ``LutBuilderHdr`` puts them)::

    post exposure -> white balance -> contrast (LogC, or ACEScc) -> colour filter -> max(0)
    -> split toning -> channel mixer -> max(0) -> shadows/midtones/highlights
    -> lift/gamma/gain -> max(0) -> hue shift and hue-vs-hue -> saturation (scaled by the
    hue-vs-sat, sat-vs-sat and lum-vs-sat curves of the colour before the hue shift)
    -> master/red/green/blue curves (in FastTonemap space) -> max(0)

Units follow Unity's inspector so a look made there can be typed in: post exposure in stops;
temperature, tint, contrast, saturation and split balance in -100..100; hue shift in degrees.
Colours are given as Unity's colour pickers show them (sRGB-encoded): the colour filter and the
shadows/midtones/highlights colours are decoded to linear like Unity's ``Color.linear``; split-toning
colours stay in gamma space, where the blend happens. Lift, gamma and gain are Unity's trackballs
``(r, g, b, w)``: a gamma-space colour and the offset slider ``w``.

Curves are control points ``((x0, y0), (x1, y1), ...)`` of monotone splines
(:mod:`torchgrade.grading.curves`), with Unity's axes: the hue curves are periodic in hue (turns), the
others clamped at their ends; in the hue and saturation curves ``y = 0.5`` changes nothing
(hue-vs-hue adds ``y - 0.5`` turns, the saturation curves multiply saturation by ``2y``); the
master/red/green/blue curves map ``[0, 1]`` to ``[0, 1]`` in FastTonemap space ``c / (1 + max(r, g, b))``.
A curve is shared by the whole batch (no per-sample curves); its ``y`` values can be learnt.

With ``aces=True`` contrast is applied in ACEScc and the rest in ACEScg with AP1 luminance, as
Unity does when ACES tone mapping is selected; ``log_space="acescct"`` grades contrast in ACEScct
instead (ACEScc's log above 2^-7 in ACEScg, a straight toe below it, as colourists' ACEScct). Whatever the working space, the grade returns
linear Rec.709, the one space every torchgrade stage takes and returns: ``ColorGrade(aces=True)``
followed by ``ToneMap("aces")`` reproduces Unity's ACES path (the final ``max(0)`` happens in
ACES2065-1 as in Unity), and no combination of stages can hand a curve the wrong primaries.
"""

from __future__ import annotations

import torch

from ..base.images import HALF_MAX, check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import color_param, is_constant, scalar_param
from ..base.planes import each_plane, joined, matrix_on, matrix_product
from ..base.controls import Control, check_given, refuse_unknown
from ..color import srgb_to_linear
from ..color.spaces import shared_matrix
from ..runtime import folded
from .curves import CurveControl, curve_is_identity
from .steps import (
    IDENTITY_MATRIX,
    IDENTITY_TRACKBALL,
    channel_mixer,
    contrast_space,
    hue_shift,
    lift_gamma_gain,
    log_contrast,
    saturation,
    saturation_curves,
    saturation_matrix,
    shadows_midtones_highlights,
    split_toning,
    white_balance_matrix,
    yrgb_curves,
)

__all__ = ["COLOR_GRADE_CONTROLS", "GRADE_SETTINGS", "color_grade", "graded_image", "color_grade_planes", "active_steps", "is_identity_control", "grade_matrix", "output_matrix"]

COLOR_GRADE_CONTROLS = {
    "aces": Control(False),
    "log_space": Control("acescc", ("acescc", "acescct")),
    "post_exposure": Control(0.0, (-20.0, 20.0)),
    "temperature": Control(0.0, (-100.0, 100.0)),
    "tint": Control(0.0, (-100.0, 100.0)),
    "contrast": Control(0.0, (-100.0, 100.0)),
    "color_filter": Control((1.0, 1.0, 1.0), (0.0, 100.0)),
    "split_shadows": Control((0.5, 0.5, 0.5), (0.0, 1.0)),
    "split_highlights": Control((0.5, 0.5, 0.5), (0.0, 1.0)),
    "split_balance": Control(0.0, (-100.0, 100.0)),
    "channel_mixer": Control(IDENTITY_MATRIX, (-2.0, 2.0)),
    "shadows": Control((1.0, 1.0, 1.0), (0.0, 100.0)),
    "midtones": Control((1.0, 1.0, 1.0), (0.0, 100.0)),
    "highlights": Control((1.0, 1.0, 1.0), (0.0, 100.0)),
    "shadows_start": Control(0.0, (0.0, 2.0)),
    "shadows_end": Control(0.3, (0.0, 2.0)),
    "highlights_start": Control(0.55, (0.0, 2.0)),
    "highlights_end": Control(1.0, (0.0, 2.0)),
    "lift": Control(IDENTITY_TRACKBALL, (-1.0, 1.0)),
    "gamma": Control(IDENTITY_TRACKBALL, (-1.0, 1.0)),
    "gain": Control(IDENTITY_TRACKBALL, (-1.0, 1.0)),
    "hue_shift": Control(0.0, (-180.0, 180.0)),
    "saturation": Control(0.0, (-100.0, 100.0)),
    "hue_vs_hue": CurveControl(periodic=True, flat=0.5),
    "hue_vs_sat": CurveControl(periodic=True, flat=0.5),
    "sat_vs_sat": CurveControl(flat=0.5),
    "lum_vs_sat": CurveControl(flat=0.5),
    "curve_master": CurveControl(),
    "curve_red": CurveControl(),
    "curve_green": CurveControl(),
    "curve_blue": CurveControl(),
}
""":class:`~torchgrade.ColorGrade`'s controls, ``{name: Control}``, in Unity's order: their defaults (identity) and ranges."""


# Which controls make each step do something; the zone limits alone change nothing.
_STEPS = {
    "post_exposure": ("post_exposure",),
    "white_balance": ("temperature", "tint"),
    "contrast": ("contrast",),
    "color_filter": ("color_filter",),
    "split_toning": ("split_shadows", "split_highlights"),
    "channel_mixer": ("channel_mixer",),
    "shadows_midtones_highlights": ("shadows", "midtones", "highlights"),
    "lift_gamma_gain": ("lift", "gamma", "gain"),
    "saturation_curves": ("hue_vs_sat", "sat_vs_sat", "lum_vs_sat"),
    "hue_shift": ("hue_shift", "hue_vs_hue"),
    "saturation": ("saturation",),
    "yrgb_curves": ("curve_master", "curve_red", "curve_green", "curve_blue"),
}


def is_identity_control(name: str, value) -> bool:
    """True when grading control or curve ``name`` set to ``value`` changes nothing.

    Examples:
        >>> is_identity_control("contrast", 0.0), is_identity_control("hue_vs_sat", ((0.0, 0.5), (0.5, 0.5)))
        (True, True)
    """
    control = COLOR_GRADE_CONTROLS[name]
    if isinstance(control, CurveControl):
        return curve_is_identity(value, control.flat)
    return is_constant(value, control.default)


def active_steps(params: dict) -> set:
    """The grading steps whose controls differ from identity (learnable controls always count).

    Examples:
        >>> sorted(active_steps({"contrast": 20, "saturation": 0.0, "shadows_end": 0.5}))
        ['contrast']
    """
    return {step for step, names in _STEPS.items() if any(name in params and not is_identity_control(name, params[name]) for name in names)}


def _grade_inputs(params: dict) -> dict:
    """Every control of the grade: the given ones, the others at their defaults; identity curves as None."""
    refuse_unknown(COLOR_GRADE_CONTROLS, params, "ColorGrade")
    inputs = {}
    for name, control in COLOR_GRADE_CONTROLS.items():
        if isinstance(control, CurveControl):
            inputs[name] = None if curve_is_identity(params.get(name), control.flat) else params[name]
        elif name not in GRADE_SETTINGS:
            inputs[name] = params.get(name, control.default)
    return inputs


def color_grade(image: torch.Tensor, aces: bool = False, log_space: str = "acescc", **params) -> torch.Tensor:
    """The whole grade, in Unity's order; steps left at identity are not computed.

    An all-identity grade returns ``image`` itself. Otherwise the input passes the non-finite policy,
    float16/bfloat16 are computed in float32, and the result is linear Rec.709 in the input's dtype. Controls given as
    numbers are checked as :class:`~torchgrade.ColorGrade` checks them (:data:`COLOR_GRADE_CONTROLS`,
    :func:`~torchgrade.base.controls.check_given`); tensors are taken as they are.

    Examples:
        >>> image = torch.rand(1, 3, 2, 2)
        >>> color_grade(image, contrast=0.0) is image
        True
        >>> color_grade(image, saturation=-100.0).std(dim=1).max().item() < 1e-6
        True
        >>> color_grade(image, contrast=500.0)
        Traceback (most recent call last):
        ...
        ValueError: contrast must lie in [-100.0, 100.0], got 500.0
    """
    check_given(COLOR_GRADE_CONTROLS, params, "ColorGrade")
    return graded_image(image, aces, log_space, **params)


def graded_image(image: torch.Tensor, aces: bool = False, log_space: str = "acescc", *, nan_free: bool = False,
                 planes: bool = False, **params) -> torch.Tensor:
    """:func:`color_grade` without checking the controls' values: for :class:`~torchgrade.ColorGrade`, which checked
    them when they were set, on every strip of a frame. ``nan_free``: ``image`` holds no NaN
    (:func:`~torchgrade.base.images.sanitize`); ``planes``: the steps run on the image's three planes
    (:func:`color_grade_planes`).

    Examples:
        >>> image = torch.rand(1, 3, 2, 2)
        >>> torch.equal(graded_image(image, contrast=20.0), color_grade(image, contrast=20.0))
        True
    """
    graded = color_grade_planes(image, aces, log_space, nan_free=nan_free, planes=planes, **params)
    return graded if graded is image else to_input_dtype(joined(graded), image)


def color_grade_planes(image: torch.Tensor, aces: bool = False, log_space: str = "acescc", *, nan_free: bool = False,
                       planes: bool = False, **params):
    """:func:`color_grade` without the cast back to the input's dtype; with ``planes``, on the image's three planes,
    returned as the graded image's three planes (a tuple) where its last steps ran on planes: the form a compiler fuses
    into one loop (:func:`~torchgrade.runtime.strips.pixelwise`), for a chain that goes on computing on planes, so no
    frame is joined only to be split again. A graded result is in the working dtype (float32 or wider); an
    all-identity grade returns ``image`` itself, in its own dtype.

    Examples:
        >>> image = torch.rand(1, 3, 2, 2)
        >>> torch.equal(color_grade_planes(image, contrast=20.0), color_grade(image, contrast=20.0))
        True
        >>> graded = color_grade_planes(image, contrast=20.0, planes=True)
        >>> type(graded).__name__, bool(torch.allclose(torch.cat(graded, dim=-3), color_grade(image, contrast=20.0), atol=1e-6))
        ('tuple', True)
    """
    check_image(image)
    p = _grade_inputs(params)
    steps = active_steps(params)
    if not steps:
        return image
    weights = "ap1" if aces else "rec709"
    like = sanitize(working_dtype(image), nan_free=nan_free)
    x = like.split(1, dim=-3) if planes else like
    # The linear steps between two non-linear ones are folded into one matrix, so each pixel sees one 3x3: post
    # exposure, white balance and the way into contrast's primaries; the way out of them and the colour filter.
    # Of plain-number controls the matrix is a constant, made once (runtime.folded).
    exposure = p["post_exposure"] if "post_exposure" in steps else None
    balance = (p["temperature"], p["tint"]) if "white_balance" in steps else None
    tint = p["color_filter"] if "color_filter" in steps else None
    if "contrast" in steps:
        encoding, into, out_of = contrast_space(aces, log_space)
        x = _applied(folded(grade_matrix, exposure, balance, into, None, like=like), x)
        x = each_plane(lambda plane: log_contrast(plane, p["contrast"], encoding), x)
        linear = folded(grade_matrix, None, None, out_of, tint, like=like)
    else:
        linear = folded(grade_matrix, exposure, balance, "srgb_to_ap1" if aces else None, tint, like=like)
    # Bounding to the non-finite policy's range after each group of gains keeps the whole documented
    # range finite: post exposure 20, contrast 100 and a filter of 100 reach 1e26, and the next squares overflow.
    x = _bounded(_applied(linear, x))
    if "split_toning" in steps:
        x = split_toning(x, p["split_shadows"], p["split_highlights"], p["split_balance"], weights)
    if "channel_mixer" in steps:
        x = channel_mixer(x, p["channel_mixer"])
    x = _bounded(x)
    if "shadows_midtones_highlights" in steps:
        x = shadows_midtones_highlights(x, p["shadows"], p["midtones"], p["highlights"], p["shadows_start"], p["shadows_end"],
                                        p["highlights_start"], p["highlights_end"], weights)
    if "lift_gamma_gain" in steps:
        x = each_plane(lambda plane: plane.clamp_min(0.0), lift_gamma_gain(x, p["lift"], p["gamma"], p["gain"]))
    factor = None
    if "saturation_curves" in steps:
        factor = saturation_curves(x, p["hue_vs_sat"], p["sat_vs_sat"], p["lum_vs_sat"], weights)
    if "hue_shift" in steps:
        x = hue_shift(x, p["hue_shift"], p["hue_vs_hue"])
    # Saturation without curves is a matrix too, folded into the way out of ACEScg: of a number, a constant; of a tensor
    # (per sample, learnable, a graph input), products of 3x3 matrices made at each call (elementwise, no MatMul).
    amount = None
    if factor is None and "saturation" in steps:
        amount = p["saturation"]
    elif "saturation" in steps or factor is not None:
        x = saturation(x, p["saturation"], weights, factor)
    if "yrgb_curves" in steps:
        x = _applied(folded(output_matrix, amount, weights, False, like=like), joined(x))
        x = yrgb_curves(x, p["curve_master"], p["curve_red"], p["curve_green"], p["curve_blue"])
        amount = None
    x = each_plane(lambda plane: plane.clamp_min(0.0), _applied(folded(output_matrix, amount, weights, aces, like=like), x))
    if aces:
        x = matrix_on(shared_matrix("ap0_to_srgb", like), x)  # aces_to_unity
    return x


def grade_matrix(exposure, balance, space, tint, *, like: torch.Tensor):
    """The linear steps of the grade before and around contrast as one matrix, ``None`` when there are none.

    In order: post ``exposure`` (stops, or None), white ``balance`` (``(temperature, tint)`` or None), the named
    :data:`~torchgrade.color.MATRICES` ``space`` (or None), the colour filter ``tint`` (sRGB-encoded, or None).

    Examples:
        >>> grade_matrix(1.0, None, None, None, like=torch.zeros(1)).diagonal().tolist()
        [2.0, 2.0, 2.0]
        >>> grade_matrix(None, None, None, None, like=torch.zeros(1)) is None
        True
    """
    linear = None
    if exposure is not None:
        linear = _diagonal(torch.exp2(scalar_param(exposure, like, "post_exposure")))
    if balance is not None:
        linear = _then(linear, white_balance_matrix(like, *balance))
    if space is not None:
        linear = _then(linear, shared_matrix(space, like))
    if tint is not None:
        linear = _then(linear, _diagonal(srgb_to_linear(color_param(tint, like, "color_filter"))))
    return linear


def output_matrix(saturation_amount, weights: str, aces: bool, *, like: torch.Tensor):
    """Saturation (``None``: none) as a matrix, then, with ``aces``, ACEScg to ACES2065-1; ``None`` when neither.

    Examples:
        >>> output_matrix(-100.0, "rec709", False, like=torch.zeros((), dtype=torch.float64))[0].tolist()  # each row: luminance weights
        [0.2126729, 0.7151522, 0.072175]
    """
    linear = None if saturation_amount is None else saturation_matrix(like, saturation_amount, weights)
    return _then(linear, shared_matrix("ap1_to_ap0", like)) if aces else linear


GRADE_SETTINGS = ("aces", "log_space")
"""Controls that choose the working space, not grading steps."""


def _diagonal(gains: torch.Tensor) -> torch.Tensor:
    """Per-channel gains ``(..., 3, 1, 1)``, or one gain (0-d or ``(B, 1, 1, 1)``), as a diagonal ``(..., 3, 3)`` matrix."""
    return (gains[..., 0] if gains.dim() else gains) * torch.eye(3, dtype=gains.dtype, device=gains.device)


def _then(first, second: torch.Tensor) -> torch.Tensor:
    """The matrix applying ``first`` (None: nothing yet), then ``second``: ``second · first``."""
    return second if first is None else matrix_product(second, first)


def _applied(linear, x):
    """An image, or its three planes as a tuple, through the folded matrix ``linear`` (None: unchanged)."""
    return x if linear is None else matrix_on(linear, x)


def _bounded(x):
    """An image, or its three planes as a tuple, bounded to ``[0, 65504]``."""
    return each_plane(lambda plane: plane.clamp(0.0, HALF_MAX), x)
