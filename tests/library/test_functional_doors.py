"""The functional API checks the controls it is given as numbers as the stages do: the same ranges, the same messages
(one table per stage); tensors pass unread, as a stage's learnable values do between its checks."""

import math

import pytest
import torch

import torchgrade as tg
from torchgrade import functional as F
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


def test_a_tone_mapping_door_refuses_an_unknown_parameter_as_tonemap_does():
    assert message(lambda: F.tonemap(IMAGE, "agx", slope=0.9)) == message(lambda: tg.ToneMap("agx", slope=0.9))
