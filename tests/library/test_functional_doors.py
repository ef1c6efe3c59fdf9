"""The functional API checks the controls it is given as numbers as the stages do: the same ranges, the same messages
(one table per stage); tensors pass unread, as a stage's learnable values do between its checks."""

import functools
import inspect
import math
import numbers
from functools import partial

import pytest
import torch

import torchgrade as tg
from torchgrade import functional as F
from torchgrade.base.stage import Stage
from torchgrade.grading.grade import COLOR_GRADE_CONTROLS
from torchgrade.grading.primary import STYLES, style_table
from torchgrade.output.dither import DITHER_CONTROLS
from torchgrade.tonemap import TONE_MAPPERS

IMAGE = torch.rand(1, 3, 4, 4)


def outside(control):
    """A value just outside ``control``'s range, or None where the range is unbounded."""
    low, high = control.range
    if not math.isinf(high):
        return high + 1.0 if isinstance(control.default, (int, float)) else tuple(high + 1.0 for _ in control.default)
    if not math.isinf(low):
        return low - 1.0 if isinstance(control.default, (int, float)) else tuple(low - 1.0 for _ in control.default)
    return None


def message(call) -> str:
    with pytest.raises(ValueError) as caught:
        call()
    return str(caught.value)


GRADE_NUMBERS = [name for name, control in COLOR_GRADE_CONTROLS.items()
                 if control.kind == "number" and control.range is not None and outside(control) is not None]


@pytest.mark.parametrize("name", GRADE_NUMBERS)
def test_color_grade_refuses_what_colorgrade_refuses_with_its_message(name):
    value = outside(COLOR_GRADE_CONTROLS[name])
    assert message(lambda: F.color_grade(IMAGE, **{name: value})) == message(lambda: tg.ColorGrade(**{name: value}))


TONEMAP_NUMBERS = [(mode, name) for mode, entry in TONE_MAPPERS.items() for name, control in entry.controls.items()
                   if control.kind == "number" and control.range is not None and outside(control) is not None]


@pytest.mark.parametrize("mode, name", TONEMAP_NUMBERS)
def test_tonemap_refuses_what_tonemap_refuses_with_its_message(mode, name):
    value = outside(TONE_MAPPERS[mode].controls[name])
    assert message(lambda: F.tonemap(IMAGE, mode, **{name: value})) == message(lambda: tg.ToneMap(mode, **{name: value}))


PRIMARY_NUMBERS = [(style, name) for style in STYLES for name, control in style_table(style).items()
                   if control.kind == "number" and control.range is not None and outside(control) is not None]


@pytest.mark.parametrize("style, name", PRIMARY_NUMBERS)
def test_primary_grade_refuses_what_primarygrade_refuses_with_its_message(style, name):
    value = outside(style_table(style)[name])
    assert message(lambda: F.primary_grade(IMAGE, style, **{name: value})) == message(lambda: tg.PrimaryGrade(style, **{name: value}))


def test_dither_refuses_what_dither_refuses_with_its_message():
    value = outside(DITHER_CONTROLS["amplitude"])
    pattern = F.dither_pattern(4)
    assert message(lambda: F.dither(IMAGE, pattern, value)) == message(lambda: tg.Dither(amplitude=value))
    assert torch.isfinite(F.dither(IMAGE, pattern, torch.tensor(0.5))).all()  # a tensor is the caller's


def test_the_issues_two_cases_and_tensors_left_unread():
    with pytest.raises(ValueError, match="contrast must lie in"):
        F.color_grade(IMAGE, contrast=500)
    with pytest.raises(ValueError, match="white_point must lie in"):
        F.tonemap(IMAGE, "hable", white_point=-1)
    assert torch.isfinite(F.color_grade(IMAGE, contrast=torch.tensor(50.0))).all()  # a tensor is the caller's
    assert len(GRADE_NUMBERS) > 10 and len(TONEMAP_NUMBERS) > 10


@pytest.mark.parametrize("door, refusal", [
    (lambda x: F.color_grade(x, contrast=10.0, nan_free=True), r"unknown ColorGrade control\(s\) \['nan_free'\]"),
    (lambda x: F.primary_grade(x, saturation=1.2, nan_free=True), r"unknown linear PrimaryGrade control\(s\) \['nan_free'\]"),
    (lambda x: F.tonemap(x, "reinhard", nan_free=True), r"tone mapper 'reinhard' takes no 'nan_free'; it takes no parameters"),
], ids=["color_grade", "primary_grade", "tonemap"])
def test_a_door_refuses_the_stages_word_that_a_frame_holds_no_nan(door, refusal):
    """``nan_free`` is what a look tells its stages about a frame a stage made; a caller's frame always takes the NaN pass."""
    image = IMAGE.clone()
    image[0, 0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match=refusal):
        door(image)


SHADOWS = (1.2, 1.0, 0.9)


@pytest.mark.parametrize("call, stage", [
    (lambda: F.shadows_midtones_highlights(IMAGE, SHADOWS, shadows_start=0.5, shadows_end=0.2),
     lambda: tg.ColorGrade(shadows_start=0.5, shadows_end=0.2)),
    (lambda: F.shadows_midtones_highlights(IMAGE, highlights_start=1.0), lambda: tg.ColorGrade(highlights_start=1.0)),
    (lambda: F.color_grade(IMAGE, shadows=SHADOWS, shadows_start=0.3, shadows_end=0.3),
     lambda: tg.ColorGrade(shadows=SHADOWS, shadows_start=0.3, shadows_end=0.3)),
    (lambda: F.log_gamma(IMAGE, SHADOWS, pivot_black=0.4, pivot_white=0.4),
     lambda: tg.PrimaryGrade("log", pivot_black=0.4, pivot_white=0.4)),
    (lambda: F.meter_luminance(IMAGE, "histogram", percents=(100.0, 0.0)),
     lambda: tg.AutoExposure(metering="histogram", low_percent=100.0, high_percent=0.0)),
    (lambda: F.meter_luminance(IMAGE, "histogram", stop_range=(3.0, 3.0)), lambda: tg.AutoExposure(min_ev=3.0, max_ev=3.0)),
], ids=["zone reversed", "zone empty at its default end", "color_grade zone empty", "pivots equal", "band reversed",
        "stop range empty"])
def test_a_door_refuses_controls_out_of_order_as_the_stage_does(call, stage):
    """Each number was checked alone, their order not: a tonal zone that ends before it starts, log gamma's pivots one
    on the other (every pixel came back at the pivot), a histogram band upside down (NaN) or of no width
    (ZeroDivisionError) were graded, where the stages refuse them."""
    assert message(call) == message(stage)


def test_a_door_leaves_alone_an_order_the_stage_leaves_alone():
    """Log metering reads no band, so its bounds may be in any order, as AutoExposure takes them; tensors are unread."""
    tg.AutoExposure(metering="log", low_percent=100.0, high_percent=0.0)
    assert torch.isfinite(F.meter_luminance(IMAGE, "log", percents=(100.0, 0.0))).all()
    assert F.log_gamma(IMAGE, SHADOWS, pivot_black=torch.tensor(0.4), pivot_white=0.4).shape == IMAGE.shape


def test_a_tone_mapping_door_refuses_an_unknown_parameter_as_tonemap_does():
    assert message(lambda: F.tonemap(IMAGE, "agx", slope=0.9)) == message(lambda: tg.ToneMap("agx", slope=0.9))


# Every function of tg.functional, every number it takes, at the values that broke them: NaN, ±inf, ±1e38 and 0. The
# arguments are read from the signatures; what a required argument holds comes from EXAMPLES, by its name, so a new
# function with an argument of a new name fails here until it is given one.

EXAMPLES = {
    "image": IMAGE, "code": IMAGE / 2, "light": IMAGE, "grid": torch.rand(1, 1, 8, 8), "pattern": F.dither_pattern(4),
    "table": torch.rand(5, 5, 5, 3), "kernel": torch.ones(1, 3, 3) / 9, "adapted": torch.tensor(0.5),
    "metered": torch.tensor(0.7), "dt": torch.tensor(0.1), "points": ((0.0, 0.1), (1.0, 0.9)), "t": torch.rand(8),
    "x": torch.tensor([0.0, 0.5, 1.0]), "y": torch.tensor([0.0, 0.3, 1.0]), "temperature": torch.tensor([10.0]),
    "tint": torch.tensor([5.0]), "stops": 0.5, "amount": 20.0, "degrees": 30.0, "color": (1.0, 0.9, 0.8),
    "lift": (1.0, 1.0, 1.0, 0.1), "gamma": (1.0, 1.0, 1.0, 0.1), "gain": (1.0, 1.0, 1.0, 0.1), "middle_grey": 0.18,
    "max_luminance": 16.0, "size": 4,
}
"""What each required argument of the functions holds (a number is walked too; a tensor is the caller's, unread)."""

KEYWORD_DOORS = {
    "color_grade": [((), COLOR_GRADE_CONTROLS, tg.ColorGrade)],
    "tonemap": [((mode,), entry.controls, partial(tg.ToneMap, mode)) for mode, entry in TONE_MAPPERS.items()],
    "primary_grade": [((style,), style_table(style), partial(tg.PrimaryGrade, style)) for style in STYLES],
}
"""The functions that take their controls as ``**keywords``: the leading arguments, table and stage of each form."""

EXTREMES = (math.nan, math.inf, -math.inf, 1e38, -1e38, 0.0)


def is_numbers(value) -> bool:
    if isinstance(value, tuple):
        return all(is_numbers(item) for item in value)
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def with_first(example, value):
    """``example`` with ``value`` in place of its first number (a colour's red, a matrix's first entry)."""
    return (with_first(example[0], value), *example[1:]) if isinstance(example, tuple) else value


def extremes_for(example) -> tuple:
    """:data:`EXTREMES`, as integers where ``example`` is one (an integer argument is walked with integers too)."""
    first = example
    while isinstance(first, tuple):
        first = first[0]
    integral = isinstance(first, int)
    return tuple(int(v) if integral and math.isfinite(v) else v for v in EXTREMES) + ((10 ** 38, -10 ** 38) if integral else ())


def numeric_arguments(function) -> list:
    """``(name, example)`` of every argument of ``function`` that takes numbers: a number or tuple of numbers as its
    default or example, or ``Param`` in its annotation."""
    found = []
    for parameter in inspect.signature(function).parameters.values():
        if parameter.kind in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD):
            continue
        example = EXAMPLES[parameter.name] if parameter.default is parameter.empty else parameter.default
        if is_numbers(example) or (example is None and "Param" in str(parameter.annotation)):
            found.append((parameter.name, example))
    return found


def required(function) -> dict:
    return {p.name: EXAMPLES[p.name] for p in inspect.signature(function).parameters.values()
            if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)}


def all_finite(result) -> bool:
    if isinstance(result, (tuple, list)):
        return all(all_finite(item) for item in result)
    return not isinstance(result, torch.Tensor) or bool(torch.isfinite(result).all())


def stage_classes() -> list:
    """Every stage class the library defines (Stage's subclasses), for the functions that check inside."""
    classes, queue = [], list(Stage.__subclasses__())
    while queue:
        cls = queue.pop()
        classes.append(cls)
        queue += cls.__subclasses__()
    return classes


@functools.lru_cache(maxsize=None)
def controls_of(build) -> frozenset:
    """The control names of the stage ``build()`` makes (built once: ACES 2.0's tables take seconds)."""
    return frozenset(build().control_table())


def stage_refusals(function, argument: str, value) -> set:
    """What the stage behind ``function`` says of ``value`` for the control ``argument`` is: the stage the door names,
    else every stage class whose table holds a control of that name (a stage that cannot be built from that control
    alone says nothing). Empty where no stage holds the control (a step ``dt``, a resampling size)."""
    control = getattr(function, "controls", {}).get(argument, argument)
    if isinstance(control, tuple):  # a pair argument: the first of its two controls took the value
        control, value = control[0], value[0]
    if hasattr(function, "stage"):
        builders = [function.stage] if function.stage is not None and control in controls_of(function.stage) else []
    else:
        builders = [cls for cls in stage_classes() if control in getattr(cls, "controls", {})]
    said = set()
    for build in builders:
        try:
            build(**{control: value})
        except ValueError as error:
            said.add(str(error))
        except TypeError:  # a stage that needs more than this control (a kernel, a table)
            pass
    return said


WALKED = [(name, argument, example) for name in F.__all__ for argument, example in numeric_arguments(getattr(F, name))]


def test_the_walk_reaches_every_function_that_takes_numbers():
    """Each function takes its numbers by name (``numeric_arguments``) or by keywords (``KEYWORD_DOORS``)."""
    keyword_functions = {name for name in F.__all__ if any(p.kind == p.VAR_KEYWORD for p in inspect.signature(getattr(F, name)).parameters.values())}
    assert keyword_functions == set(KEYWORD_DOORS)
    walked = {name for name, _, _ in WALKED}
    assert {"post_exposure", "contrast", "white_balance", "saturation", "hue_shift", "reinhard_extended"} <= walked
    assert len(WALKED) > 80


@pytest.mark.parametrize("name, argument, example", WALKED, ids=[f"{n}-{a}" for n, a, _ in WALKED])
def test_every_number_of_every_function_is_refused_as_its_stage_refuses_it_or_gives_finite_pixels(name, argument, example):
    function = getattr(F, name)
    for extreme in extremes_for(example):
        value = with_first(example, extreme) if example is not None else extreme
        try:
            result = function(**{**required(function), argument: value})
        except ValueError as error:  # where a stage holds the control, in its words; elsewhere a clear refusal
            said = stage_refusals(function, argument, value)
            assert not said or str(error) in said, f"{name}({argument}={value!r}): {error}"
        else:
            assert all_finite(result), f"{name}({argument}={value!r}) is not finite"


@pytest.mark.parametrize("name", sorted(KEYWORD_DOORS))
def test_every_control_given_by_keyword_is_refused_as_its_stage_refuses_it_or_gives_finite_pixels(name):
    function = getattr(F, name)
    for leading, table, stage in KEYWORD_DOORS[name]:
        for control_name, control in table.items():
            if control.kind not in ("number", "int"):
                continue
            for extreme in extremes_for(control.default if control.default is not None else 0.0):
                value = with_first(control.default, extreme) if control.default is not None else extreme
                try:
                    result = function(IMAGE, *leading, **{control_name: value})
                except ValueError as error:
                    assert str(error) == message(lambda stage=stage, controls={control_name: value}: stage(**controls)), f"{name}{leading}({control_name}={value!r})"
                else:
                    assert all_finite(result), f"{name}{leading}({control_name}={value!r}) is not finite"


def test_a_door_checks_a_number_given_by_position_as_by_name():
    with pytest.raises(ValueError, match="post_exposure must lie in"):
        F.post_exposure(IMAGE, 1e38)
    with pytest.raises(ValueError, match="white_point must lie in"):
        F.reinhard_extended(IMAGE, 0.0)
    assert F.post_exposure(IMAGE, torch.tensor(1e38)).shape == IMAGE.shape  # a tensor is the caller's: not read
