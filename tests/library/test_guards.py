"""Inputs as newcomers bring them: RGBA frames, 0..255 floats, 8-bit tensors, frames larger than a strip.

* **Alpha** passes through every stage unchanged (``Stage.__call__``, :func:`torchgrade.base.images.with_alpha`): the RGB of
  a ``(B, 4, H, W)`` frame comes out as that of its ``(B, 3, H, W)`` colour, the fourth channel bit for bit.
* **0..255 floats** given as linear light warn, naming the fix; HDR and [0, 1] frames do not.
* **Errors name the caller's shape**, also for a frame larger than a CPU strip (2^17 pixels on 2 threads) and for an
  RGBA frame whose colour the stage saw.
"""

from __future__ import annotations

import copy
import re
import warnings
from pathlib import Path

import pytest
import torch

import torchgrade as tg
from runtime.test_device import CASES  # tests/runtime, a namespace package beside this folder
from torchgrade.base.stage import Stage
from torchgrade.lut import LUT_BACKENDS

EXR = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "exr"

NO_ALPHA = {
    "random-postfx": "RandomPostFX is a kornia layer, not a stage: it takes (B, 3, H, W)",
    "random-postfx-tonemaps": "RandomPostFX is a kornia layer, not a stage",
    "match-controls": "a look fitter's parameterisation, not a stage",
    "match-residual": "a look fitter's residual LUT, not a stage",
}
"""Cases of ``tests/runtime/test_device.py`` that are no stage (nor a look of stages), and why."""

ALPHA_CASES = sorted(name for name in CASES if name not in NO_ALPHA and not name.endswith("-export")
                     and not (name.startswith("lut-") and name.rsplit("-", 1)[-1] in LUT_BACKENDS))
"""Every stage and look of ``tests/runtime/test_device.py``; export forms are what an ONNX graph traces, on colour only."""


def _frames() -> tuple:
    """An HDR colour batch (2, 3, 24, 32) and the same colour with an alpha of its own, (2, 4, 24, 32)."""
    generator = torch.Generator().manual_seed(0)
    colour = torch.rand(2, 3, 24, 32, generator=generator) ** 3 * 12.0
    alpha = torch.rand(2, 1, 24, 32, generator=generator)
    return colour, torch.cat((colour, alpha), dim=1)


def test_every_stage_case_is_run_with_alpha():
    stages = {name for name, make in CASES.items() if isinstance(make(), Stage) and not name.endswith("-export")}
    assert stages <= set(ALPHA_CASES)


@pytest.mark.parametrize("name", ALPHA_CASES)
def test_alpha_passes_through_unchanged_and_the_colour_is_graded_as_without_it(name):
    module = CASES[name]()
    colour, rgba = _frames()
    expected = copy.deepcopy(module)(colour)  # a copy each: eye adaptation keeps state between frames
    out = copy.deepcopy(module)(rgba)
    assert out.shape == rgba.shape
    assert torch.equal(out[:, 3:], rgba[:, 3:])
    torch.testing.assert_close(out[:, :3], expected, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("name", ["tonemap-aces", "grade", "primary-log", "bloom-additive", "exposure-adapting", "lut-linear", "postfx"])
def test_gradients_reach_the_colour_as_without_alpha_and_alpha_gets_its_own(name):
    module = CASES[name]()
    colour, rgba = _frames()
    colour.requires_grad_(True)
    rgba.requires_grad_(True)
    weights = torch.linspace(0.5, 1.5, 24 * 32).reshape(24, 32)
    (copy.deepcopy(module)(colour) * weights).sum().backward()
    (copy.deepcopy(module)(rgba) * weights).sum().backward()
    assert colour.grad.abs().sum() > 0
    torch.testing.assert_close(rgba.grad[:, :3], colour.grad, rtol=1e-5, atol=1e-6)
    assert torch.equal(rgba.grad[:, 3], weights.expand(2, 24, 32))  # alpha out is alpha in: d out / d alpha = 1


def test_an_exr_with_alpha_goes_through_a_look_with_its_alpha_kept():
    rgba = tg.io.read_exr(EXR / "CandleGlass.exr")[None, :, 400:560, 240:400]  # the glass's edge
    assert rgba.shape == (1, 4, 160, 160) and 0.1 < rgba[:, 3].mean() < 0.9  # a cut-out: alpha neither 0 nor 1 everywhere
    look = tg.PostFX(exposure={}, bloom={"intensity": 0.5}, grade={"contrast": 20, "saturation": 10}, tonemap="aces",
                     display={"encoding": "srgb"})
    out = copy.deepcopy(look)(rgba)
    assert torch.equal(out[:, 3:], rgba[:, 3:])
    torch.testing.assert_close(out[:, :3], copy.deepcopy(look)(rgba[:, :3].contiguous()), rtol=1e-6, atol=1e-6)


# ---------------------------------------------------------------------------------------------- 0..255 floats


def _caught(call) -> list:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        call()
    return [w for w in caught if "0..255" in str(w.message)]


def _eight_bit(shape=(1, 3, 270, 480)) -> torch.Tensor:
    return torch.randint(0, 256, shape, generator=torch.Generator().manual_seed(1)).float()


def _whole_number_lamps() -> torch.Tensor:
    """A synthetic HDR frame in whole numbers: black with lamps of 8 and 60 and a strip of 2 (warned before)."""
    image = torch.zeros(1, 3, 270, 480)
    image[..., ::9, ::7] = 8.0
    image[..., ::30, ::11] = 60.0
    image[..., :, 100:110] = 2.0
    return image


@pytest.mark.parametrize("module", [tg.ToneMap("neutral"), tg.ColorGrade(contrast=10), tg.PostFX(exposure={}, tonemap="aces")],
                         ids=["tonemap", "grade", "look"])
def test_0_to_255_floats_warn_once_with_the_fix(module):
    image = _eight_bit()

    def three_frames():
        for _ in range(3):
            module(image)

    caught = _caught(three_frames)
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "divide by 255" in message and "tg.color.srgb_to_linear" in message and 'RandomPostFX(input_space="srgb")' in message


@pytest.mark.parametrize("image", [
    torch.rand(1, 3, 270, 480) * 200.0,  # HDR: fractions
    torch.rand(1, 3, 270, 480),  # display-referred [0, 1]
    _eight_bit() / 255.0,  # 8-bit data divided by 255
    torch.full((1, 3, 270, 480), 8.0),  # one grey, whole
    _eight_bit() * 2.0,  # whole numbers beyond 255
    _eight_bit() - 128.0,  # whole numbers below 0
    _whole_number_lamps(),  # synthetic HDR: a few whole levels (black, lamps of 8 and 60)
], ids=["hdr", "unit", "divided", "one-grey", "beyond-255", "negative", "whole-lamps"])
def test_frames_that_are_not_0_to_255_data_do_not_warn(image):
    assert _caught(lambda: tg.ToneMap("neutral")(image)) == []


def test_the_warning_judges_a_frame_by_its_whole_sample_not_its_corner():
    image = _eight_bit()
    image[..., 135:, :] += 0.5  # the lower half holds fractions: no 8-bit picture
    assert _caught(lambda: tg.ToneMap("neutral")(image)) == []


def test_an_rgba_frame_is_judged_by_its_colour():
    rgba = torch.cat((_eight_bit(), torch.rand(1, 1, 270, 480)), dim=1)  # 0..255 colour, alpha in [0, 1]
    assert len(_caught(lambda: tg.ToneMap("neutral")(rgba))) == 1


def test_an_integer_image_is_refused_naming_the_fix():
    with pytest.raises(TypeError) as error:
        tg.ToneMap("neutral")(torch.zeros(1, 3, 8, 8, dtype=torch.uint8))
    message = str(error.value)
    assert "/ 255" in message and "tg.color.srgb_to_linear" in message and 'RandomPostFX(input_space="srgb")' in message


# ---------------------------------------------------------------------------------------------- the caller's shapes

BIG = (810, 1000)
"""CandleGlass's size: 810,000 pixels, several CPU strips."""


def _modules() -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", tg.lut.LUTAccuracyWarning)  # a 9³ table: its accuracy is not what is tested
        lut = tg.bake_lut(tg.ToneMap("aces"), size=9)
        baked = tg.PostFX(grade={"contrast": 10}, tonemap="aces").to_lut(size=9)
    return {
        "grade": tg.ColorGrade(contrast=10),
        "primary": tg.PrimaryGrade(saturation=1.2),
        "tonemap": tg.ToneMap("neutral"),
        "lut": lut,
        "bloom": tg.Bloom(intensity=0.5),
        "exposure": tg.AutoExposure(),
        "look": tg.PostFX(exposure={}, grade={"contrast": 10}, tonemap="aces"),
        "strip-look": tg.PostFX(grade={"contrast": 10}, tonemap="aces"),  # its first stage runs in strips
        "baked-look": baked,
    }


MODULES = _modules()


@pytest.mark.parametrize("name", sorted(MODULES))
@pytest.mark.parametrize("image, error", [
    (torch.rand(1, 5, *BIG), ValueError),
    (torch.rand(1, 2, *BIG), ValueError),
    (torch.rand(1, 5, 0, BIG[1]), ValueError),
    (torch.zeros(1, 5, *BIG, dtype=torch.int32), TypeError),
], ids=["5-channels", "2-channels", "empty", "int32"])
def test_bad_frames_larger_than_a_strip_are_named_by_the_callers_shape(name, image, error):
    with pytest.raises(error) as raised:
        MODULES[name](image)
    if error is ValueError:
        assert str(tuple(image.shape)) in str(raised.value)


@pytest.mark.parametrize("module", [
    tg.ColorGrade(contrast=torch.tensor([10.0, 20.0])),
    tg.PrimaryGrade(saturation=torch.tensor([0.5, 1.5])),
    tg.ToneMap("reinhard_extended", white_point=torch.tensor([2.0, 3.0])),
    tg.PostFX(grade=tg.ColorGrade(contrast=torch.tensor([10.0, 20.0])), tonemap="aces"),
], ids=["grade", "primary", "tonemap", "look"])
@pytest.mark.parametrize("channels", [3, 4])
def test_a_per_sample_control_against_another_batch_names_the_callers_frame(module, channels):
    image = torch.rand(3, channels, *BIG)
    with pytest.raises(ValueError, match=re.escape(f"the image has shape {(3, channels, *BIG)}")):
        module(image)
