"""The pure, differentiable functions behind torchgrade's modules, in one namespace.

Examples:
    >>> import torch
    >>> from torchgrade import functional as F
    >>> image = torch.rand(1, 3, 4, 4) * 8
    >>> out = F.tonemap(F.color_grade(image, contrast=20), "neutral")
    >>> bool(out.min() >= 0 and out.max() <= 1)
    True

Each function that computes a stage's step checks the numbers it is given for that stage's controls as the stage does:
the same table, the same message (:data:`DOORS`); tensors pass unread, as a stage's learnable values do between its
checks, so a training loop's per-sample controls cost no read back from the device.

    >>> F.post_exposure(image, 1e38)
    Traceback (most recent call last):
    ...
    ValueError: post_exposure must lie in [-20.0, 20.0], got 1e+38
"""

import functools
import inspect
from functools import partial
from typing import Callable, NamedTuple, Optional

import torch

from .base.controls import Control, check_given
from .bloom import Bloom, bloom, bloom_threshold, convolution_bloom, fft_convolve
from .bloom.layer import MAX_FRAME_SIDE
from .color import (
    aces_to_acescc,
    aces_to_acescg,
    aces_to_unity,
    acescc_to_aces,
    acescct_to_linear,
    acescg_to_aces,
    acescg_to_unity,
    hlg_inverse_oetf,
    hlg_oetf,
    hsv_to_rgb,
    linear_to_acescct,
    linear_to_lms,
    linear_to_logc,
    linear_to_pq,
    linear_to_srgb,
    lms_to_linear,
    logc_to_linear,
    luminance,
    pq_to_linear,
    rgb_to_hsv,
    srgb_to_linear,
    unity_to_aces,
    unity_to_acescg,
)
from .exposure import (
    adapt_luminance,
    area_resize,
    auto_exposure,
    exposure_operator,
    halving_average,
    meter_luminance,
)
from .grading.curves import evaluate_curve, monotone_tangents
from .exposure import AutoExposure
from .exposure.adaptation import BOUNDS, CONTROLS, check_bounds, check_step, checked_control
from .grading.grade import COLOR_GRADE_CONTROLS, color_grade
from .grading.layer import ColorGrade, PrimaryGrade, check_zone
from .grading.primary import (
    brightness,
    check_pivots,
    linear_contrast,
    log_gamma,
    offset_exposure,
    primary_grade,
    primary_log_contrast,
    primary_saturation,
    style_table,
)
from .grading.steps import (
    channel_mixer,
    color_filter,
    contrast,
    fast_tonemap,
    fast_tonemap_inverse,
    hue_shift,
    lift_gamma_gain,
    lift_gamma_gain_coefficients,
    post_exposure,
    saturation,
    saturation_curves,
    shadows_midtones_highlights,
    split_toning,
    white_balance,
    white_balance_coefficients,
    yrgb_curves,
)
from .lut import apply_lut
from .output.dither import dither, dither_pattern
from .output.layer import Display, Dither
from .tonemap import (
    TONE_MAPPERS,
    aces,
    aces2_hdr,
    aces2_sdr,
    aces_hill,
    aces_narkowicz,
    aces_reference,
    agx,
    agx_godot,
    filmic,
    hable,
    khronos_pbr_neutral,
    neutral,
    reinhard,
    reinhard_extended,
    reinhard_luminance,
    tonemap,
    unreal_filmic,
)
from .tonemap.aces2 import aces2_output
from .tonemap.layer import ToneMap

__all__ = [
    "acescct_to_linear",
    "hlg_inverse_oetf",
    "hlg_oetf",
    "linear_to_acescct",
    "linear_to_pq",
    "pq_to_linear",
    "aces2_sdr",
    "aces2_hdr",
    "aces2_output",
    "aces_to_acescc",
    "aces_to_acescg",
    "aces_to_unity",
    "acescc_to_aces",
    "acescg_to_aces",
    "acescg_to_unity",
    "hsv_to_rgb",
    "linear_to_lms",
    "linear_to_logc",
    "linear_to_srgb",
    "lms_to_linear",
    "logc_to_linear",
    "luminance",
    "rgb_to_hsv",
    "srgb_to_linear",
    "unity_to_aces",
    "unity_to_acescg",
    "tonemap",
    "reinhard",
    "reinhard_extended",
    "reinhard_luminance",
    "neutral",
    "aces",
    "hable",
    "filmic",
    "unreal_filmic",
    "aces_reference",
    "aces_hill",
    "aces_narkowicz",
    "agx",
    "agx_godot",
    "khronos_pbr_neutral",
    "color_grade",
    "post_exposure",
    "white_balance",
    "white_balance_coefficients",
    "contrast",
    "color_filter",
    "split_toning",
    "channel_mixer",
    "shadows_midtones_highlights",
    "lift_gamma_gain",
    "lift_gamma_gain_coefficients",
    "saturation_curves",
    "hue_shift",
    "saturation",
    "fast_tonemap",
    "fast_tonemap_inverse",
    "yrgb_curves",
    "evaluate_curve",
    "monotone_tangents",
    "primary_grade",
    "offset_exposure",
    "brightness",
    "linear_contrast",
    "primary_log_contrast",
    "log_gamma",
    "primary_saturation",
    "dither",
    "dither_pattern",
    "auto_exposure",
    "meter_luminance",
    "adapt_luminance",
    "exposure_operator",
    "area_resize",
    "halving_average",
    "bloom",
    "bloom_threshold",
    "convolution_bloom",
    "fft_convolve",
    "apply_lut",
]


class StageCheck(NamedTuple):
    """A stage and its check of the numbers given for its controls: ``check({control: value})`` raises the stage's
    ``ValueError`` (``stage`` is ``None`` for a function no stage runs)."""

    stage: Optional[Callable]
    check: Callable


def checked(function, checks: StageCheck, arguments: dict):
    """``function``, checking first the numbers it is given for a stage's controls: ``arguments`` maps each argument to
    the control it is (or to a pair of controls, for an argument that holds a pair), checked by ``checks.check``. A
    tensor is not read (on a GPU each read waits for the device). The door keeps ``controls`` (``arguments``) and
    ``stage``, for ``help()`` and the tests.

    Examples:
        >>> gain = StageCheck(None, partial(check_given, {"gain": Control(1.0, (0.0, 2.0))}, owner="Gain"))
        >>> scaled = checked(lambda image, gain=1.0: image * gain, gain, {"gain": "gain"})
        >>> scaled(torch.ones(1), 3.0)
        Traceback (most recent call last):
        ...
        ValueError: gain must lie in [0.0, 2.0], got 3.0
    """
    parameters = inspect.signature(function).parameters
    names = list(parameters)
    unknown = set(arguments) - set(names)
    if unknown and not any(parameter.kind is parameter.VAR_KEYWORD for parameter in parameters.values()):
        raise TypeError(f"{function.__name__} has no argument {sorted(unknown)}")
    positions = {argument: names.index(argument) if argument in names else len(names) for argument in arguments}

    @functools.wraps(function)
    def door(*args, **kwargs):
        given = {}
        for argument, control in arguments.items():
            at = positions[argument]
            if argument not in kwargs and at >= len(args):
                continue  # its default, inside the range (or a keyword not given)
            value = kwargs[argument] if argument in kwargs else args[at]
            if not isinstance(control, tuple):
                given[control] = value
            elif isinstance(value, (tuple, list)):
                given.update(zip(control, value))
        checks.check(given)
        return function(*args, **kwargs)

    vars(door).update(controls=dict(arguments), stage=checks.stage)
    return door


def _table(table: dict, owner: str) -> Callable:
    return partial(check_given, table, owner=owner)


def _given_or_default(given: dict, table: dict, names) -> list | None:
    """The values of the controls ``names``, as given or at their defaults in ``table``; ``None`` where one is a tensor
    (not read) or none of them was given (the defaults are in order)."""
    values = [given.get(name, table[name].default) for name in names]
    if not given.keys() & set(names) or any(isinstance(value, torch.Tensor) for value in values):
        return None
    return values


def _grade_checks(given: dict) -> None:
    """:class:`~torchgrade.ColorGrade`'s checks: each control with its table, each tonal zone's start below its end."""
    check_given(COLOR_GRADE_CONTROLS, given, "ColorGrade")
    for zone in ("shadows", "highlights"):
        edges = _given_or_default(given, COLOR_GRADE_CONTROLS, (f"{zone}_start", f"{zone}_end"))
        if edges is not None:
            start, end = edges
            check_zone(start, end, zone)


def _exposure_checks(given: dict) -> None:
    """:class:`~torchgrade.AutoExposure`'s checks: each control as the stage checks it (a positive one named as such),
    the step ``dt`` as its forward does, the bounds in order (:func:`~torchgrade.exposure.adaptation.check_bounds`)."""
    for name, value in given.items():
        if name == "dt":
            check_step(value)
        elif not isinstance(value, torch.Tensor):
            checked_control(name, value)
    bounds = _given_or_default(given, CONTROLS, BOUNDS)
    if bounds is not None:
        check_bounds(*bounds)


def _tone_mapper(mode: str) -> StageCheck:
    return StageCheck(partial(ToneMap, mode), _table(TONE_MAPPERS[mode].controls, f"ToneMap({mode!r})"))


def _primary_checks(given: dict, style: str) -> None:
    """:class:`~torchgrade.PrimaryGrade`'s checks: each control with the style's table, a log grade's pivots apart."""
    table = style_table(style)
    check_given(table, given, f"{style} PrimaryGrade")
    pivots = _given_or_default(given, table, ("pivot_black", "pivot_white")) if style == "log" else None
    if pivots is not None:
        check_pivots(*pivots)


def _primary(style: str) -> StageCheck:
    return StageCheck(partial(PrimaryGrade, style), partial(_primary_checks, style=style))


def _same(*names: str) -> dict:
    return {name: name for name in names}


_GRADE = StageCheck(ColorGrade, _grade_checks)
_EXPOSURE = StageCheck(AutoExposure, _exposure_checks)
_DISPLAY = StageCheck(Display, _table(Display.controls, "Display"))

_ZONES = ("shadows_start", "shadows_end", "highlights_start", "highlights_end")

DOORS = {
    color_grade: (_GRADE, _same(*_ZONES)),
    post_exposure: (_GRADE, {"stops": "post_exposure"}),
    white_balance: (_GRADE, _same("temperature", "tint")),
    white_balance_coefficients: (_GRADE, _same("temperature", "tint")),
    contrast: (_GRADE, {"amount": "contrast"}),
    color_filter: (_GRADE, {"color": "color_filter"}),
    split_toning: (_GRADE, {"shadows": "split_shadows", "highlights": "split_highlights", "balance": "split_balance"}),
    channel_mixer: (_GRADE, {"mixer": "channel_mixer"}),
    shadows_midtones_highlights: (_GRADE, _same("shadows", "midtones", "highlights", *_ZONES)),
    lift_gamma_gain: (_GRADE, _same("lift", "gamma", "gain")),
    lift_gamma_gain_coefficients: (_GRADE, _same("lift", "gamma", "gain")),
    hue_shift: (_GRADE, {"degrees": "hue_shift"}),
    saturation: (_GRADE, {"amount": "saturation"}),
    offset_exposure: (_primary("linear"), _same("offset", "exposure")),
    linear_contrast: (_primary("linear"), _same("contrast", "pivot")),
    primary_saturation: (_primary("linear"), {"amount": "saturation"}),
    brightness: (_primary("log"), {"amount": "brightness"}),
    primary_log_contrast: (_primary("log"), _same("contrast", "pivot")),
    log_gamma: (_primary("log"), _same("gamma", "pivot_black", "pivot_white")),
    **{entry.curve: (_tone_mapper(mode), _same(*entry.controls))
       for mode, entry in TONE_MAPPERS.items() if entry.controls and entry.curve is globals().get(mode)},
    aces2_output: (_tone_mapper("aces2_hdr"), _same("peak_luminance")),
    bloom_threshold: (StageCheck(Bloom, _table(Bloom.controls, "Bloom")), _same("threshold", "knee")),
    meter_luminance: (_EXPOSURE, {"metering": "metering", "stop_range": ("min_ev", "max_ev"),
                                  "percents": ("low_percent", "high_percent"), "middle_grey": "middle_grey",
                                  "block": "histogram_block"}),
    adapt_luminance: (_EXPOSURE, _same("dt", "speed", "speed_to_light", "speed_to_dark")),
    exposure_operator: (_EXPOSURE, _same("middle_grey", "max_luminance")),
    area_resize: (StageCheck(None, _table({"size": Control(64, (1, MAX_FRAME_SIDE))}, "area_resize")), _same("size")),
    dither_pattern: (StageCheck(Dither, _table(Dither.controls, "Dither")), _same("size")),
    linear_to_pq: (_DISPLAY, {"reference": "peak_luminance"}),
    pq_to_linear: (_DISPLAY, {"reference": "peak_luminance"}),
}
"""The functions that compute a step of a stage without checking its controls, each with its stage's
:class:`StageCheck` and ``{argument: control}``: this module's names are those functions behind their checks
(:func:`checked`), which check what the stage checks of its controls together too (a tonal zone's ends, log gamma's
pivots, exposure's bounds). The stages' own doors (:func:`tonemap`, :func:`primary_grade`, :func:`bloom`,
:func:`convolution_bloom`, :func:`auto_exposure`, :func:`dither`) check inside, and :func:`color_grade` its controls one
by one (its door here orders its tonal zones); the stages call the unchecked forms."""

globals().update({function.__name__: checked(function, *door) for function, door in DOORS.items()})
