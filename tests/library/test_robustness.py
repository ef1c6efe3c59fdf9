"""Bad input, unusual layouts and untrusted files, across every public module."""

import os

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import torchgrade as tg

IDENTITY_CUBE = tg.bake_lut(lambda x: x * 0.5, size=2, shaper="linear")


def _modules():
    """Every public layer with its controls set to something that changes the image."""
    lut = tg.bake_lut(torch.nn.Sequential(tg.ColorGrade(contrast=20), tg.ToneMap("aces")), size=9)
    return {
        "tonemap": tg.ToneMap("aces"),
        "grade": tg.ColorGrade(contrast=20, saturation=10, hue_shift=10, temperature=10),
        "grade-aces": tg.ColorGrade(aces=True, contrast=20, split_shadows=(0.4, 0.5, 0.6)),
        "bloom-additive": tg.Bloom(intensity=0.5, downscale_limit=1),
        "bloom-scattering": tg.Bloom(mode="scattering", intensity=0.5, downscale_limit=1),
        "autoexposure": tg.AutoExposure(),
        "lut-tetrahedral": lut,
        "postfx": tg.PostFX(exposure={}, bloom={"intensity": 0.4}, grade={"contrast": 10}, tonemap="neutral"),
        "augment": tg.RandomPostFX(contrast=(-20, 20), saturation=(-20, 20)),
    }


MODULES = _modules()


@pytest.mark.parametrize("name", sorted(MODULES))
@pytest.mark.parametrize(
    "image, error, message",
    [
        (torch.rand(1, 2, 8, 8), ValueError, "3 colour channels"),
        (torch.rand(1, 5, 8, 8), ValueError, "3 colour channels"),
        (torch.ones(1, 3, 8, 8, dtype=torch.int64), TypeError, "floating-point"),
        (torch.ones(1, 3, 8, 8, dtype=torch.complex64), TypeError, "floating-point"),
        (torch.rand(1, 3, 0, 8), ValueError, "empty"),
        (torch.rand(0, 3, 8, 8), ValueError, "empty"),
    ],
    ids=["2-channels", "5-channels", "int64", "complex64", "zero-height", "zero-batch"],
)
def test_bad_images_raise_clear_errors(name, image, error, message):
    with pytest.raises(error, match=message):
        MODULES[name](image)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_one_pixel_images_work(name):
    out = MODULES[name](torch.full((2, 3, 1, 1), 0.5))
    assert out.shape == (2, 3, 1, 1) and torch.isfinite(out).all()


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n != "augment"))
def test_non_contiguous_and_channels_last_inputs_give_the_same_result(name):
    module = MODULES[name]
    image = torch.rand(2, 3, 24, 20) * 4
    expected = module(image)
    channels_last = image.contiguous(memory_format=torch.channels_last)
    transposed = image.transpose(-1, -2).contiguous().transpose(-1, -2)  # same values, non-contiguous
    assert not transposed.is_contiguous()
    torch.testing.assert_close(module(channels_last), expected, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(module(transposed), expected, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: tg.ColorGrade(saturation=-101), r"saturation must lie in \[-100.0, 100.0\]"),
        (lambda: tg.ColorGrade(temperature=torch.tensor([0.0, 500.0])), "temperature must lie in"),
        (lambda: tg.ToneMap("hable", white_point=0.0), "white_point must lie in"),
        (lambda: tg.Bloom(scatter=0.99), "scatter"),
        (lambda: tg.Bloom(intensity=-1.0), "intensity"),
        (lambda: tg.Bloom(mode="glare"), "mode"),
        (lambda: tg.AutoExposure(middle_grey=0.0), "middle_grey"),
        (lambda: tg.AutoExposure(metering="median"), "metering"),
        (lambda: tg.bake_lut(lambda x: x, size=300), "LUT size must be an integer from 2 to 256"),
        (lambda: tg.PostFX.from_config({"grade": {"contrast": 150}}), "grade.contrast must lie in"),
        (lambda: tg.PostFX.from_config({"bloom": {"radius": 3}}), "unknown key 'bloom.radius'"),
        (lambda: tg.RandomPostFX(contrast=(20, -20)), "contrast"),
    ],
)
def test_out_of_range_parameters_name_the_parameter(build, message):
    with pytest.raises(ValueError, match=message):
        build()


@pytest.mark.parametrize(
    "module",
    [
        tg.ColorGrade(contrast=torch.tensor([10.0, 20.0, 30.0])),
        tg.ToneMap("reinhard_extended", white_point=torch.tensor([2.0, 3.0, 4.0])),
        tg.Bloom(intensity=torch.tensor([0.1, 0.2, 0.3]), downscale_limit=1),
        tg.AutoExposure(middle_grey=torch.tensor([0.1, 0.2, 0.3])),
    ],
    ids=["grade", "tonemap", "bloom", "autoexposure"],
)
def test_per_sample_parameters_with_the_wrong_batch_size_are_clear_errors(module):
    with pytest.raises(ValueError, match="per-sample|batch|B ="):
        module(torch.rand(2, 3, 16, 16))


# ---------------------------------------------------------------- untrusted .cube files

CUBE_WORDS = st.sampled_from(
    ["TITLE", '"x"', "LUT_3D_SIZE", "LUT_1D_SIZE", "DOMAIN_MIN", "DOMAIN_MAX", "LUT_3D_INPUT_RANGE",
     "LUT_1D_INPUT_RANGE", "#", "0", "1", "2", "-1", "0.5", "1e9", "nan", "inf", "-inf", "65", "257",
     "99999999999", "1e-300", "x", "\x00", "é", "0x10", "2.0.0", ""]
)
CUBE_LINES = st.lists(st.lists(CUBE_WORDS, max_size=5).map(" ".join), max_size=40).map("\n".join)


def _valid_cube_text(tmp_path) -> str:
    path = tmp_path / "valid.cube"
    tg.io.write_cube(path, IDENTITY_CUBE)
    return path.read_text()


@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=CUBE_LINES)
def test_read_cube_raises_only_value_error_on_generated_files(tmp_path, text):
    path = tmp_path / "fuzz.cube"
    path.write_text(text, encoding="utf-8")
    try:
        lut = tg.io.read_cube(path)
    except ValueError:
        return
    assert torch.isfinite(lut.table).all()


@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_read_cube_raises_only_value_error_on_damaged_valid_files(tmp_path, data):
    original = _valid_cube_text(tmp_path).encode()
    cut = data.draw(st.integers(0, len(original)))
    junk = data.draw(st.binary(max_size=20))
    damaged = original[:cut] + junk + original[cut + data.draw(st.integers(0, 20)):]
    path = tmp_path / "damaged.cube"
    path.write_bytes(damaged)
    try:
        lut = tg.io.read_cube(path)
    except ValueError:
        return
    assert torch.isfinite(lut.table).all()


def test_absurd_declared_size_is_rejected_before_allocating(tmp_path):
    path = tmp_path / "huge.cube"
    path.write_text("LUT_3D_SIZE 100000\n0 0 0\n")
    with pytest.raises(ValueError, match="LUT_3D_SIZE"):
        tg.io.read_cube(path)


def test_failed_write_cube_leaves_no_file_and_keeps_the_old_one(tmp_path):
    path = tmp_path / "keep.cube"
    tg.io.write_cube(path, IDENTITY_CUBE)
    before = path.read_bytes()
    with pytest.raises(ValueError):
        tg.io.write_cube(path, IDENTITY_CUBE, title='bad "title"')
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["keep.cube"]
