"""Tone mappers against independent float64 formulas, invariants, gradients and extremes."""

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.functional import tonemap

from reference.pixels import pixels, rows
from reference.tonemap import hdr_samples, REFERENCES


OPENCOLORIO_REFERENCED = {"aces2", "aces2_hdr"}
"""Modes checked against OpenColorIO's builtin ACES 2.0 views instead (tests/tonemap/test_aces2.py)."""


def test_every_mode_has_a_reference():
    assert set(REFERENCES) | OPENCOLORIO_REFERENCED == set(tg.TONEMAP_MODES)


@pytest.mark.parametrize("mode", sorted(REFERENCES))
def test_matches_independent_float64_formula(mode, device):
    rgb = hdr_samples()
    ours = rows(tonemap(pixels(rgb, device=device), mode))
    np.testing.assert_allclose(ours, REFERENCES[mode](rgb), atol=1e-9)


def test_neutral_white_point_is_about_4035():
    values = torch.tensor([4.0, 4.035, 4.1], dtype=torch.float64).reshape(1, 1, 1, 3).expand(1, 3, 1, 3)
    out = tonemap(values, "neutral")[0, 0, 0]
    assert out[0] < 1.0 and out[2] == 1.0 and out[1] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_greys_map_monotonically_into_unit_range(mode):
    grey = torch.logspace(-6, 4, 2000, dtype=torch.float64).reshape(1, 1, 1, -1).expand(1, 3, 1, -1)
    out = tonemap(grey, mode)
    assert out.min() >= 0 and out.max() <= 1
    if mode == "aces":
        # Below 1e-3 Unity's fit lifts blacks by up to 1.4e-4 (its xyY step divides by max(X+Y+Z, 1e-4)),
        # under half an 8-bit sRGB code and not monotonic; the reference test above covers that region.
        out = out[..., grey[0, 0, 0] > 1e-3]
    assert (out[..., 1:] >= out[..., :-1] - 1e-12).all()


@pytest.mark.parametrize("mode", ["reinhard_extended", "reinhard_luminance"])
def test_white_point_maps_to_one(mode):
    grey = torch.full((1, 3, 1, 1), 7.0, dtype=torch.float64)
    # Rec.709 weights sum to 1.0000001, so a grey of 7 has luminance 7.0000007.
    torch.testing.assert_close(tonemap(grey, mode, white_point=7.0), torch.ones_like(grey), atol=1e-6, rtol=0)


@pytest.mark.parametrize("mode", ["reinhard", "reinhard_extended", "reinhard_luminance", "neutral", "aces", "hable"])
def test_gradcheck(mode):
    image = (torch.rand(1, 3, 3, 3, dtype=torch.float64) * 3 + 0.05).requires_grad_()
    assert torch.autograd.gradcheck(lambda x: tonemap(x, mode), (image,))


def test_gradcheck_with_respect_to_parameters():
    image = torch.rand(2, 3, 3, 3, dtype=torch.float64) * 3 + 0.05
    white = torch.tensor([5.0, 9.0], dtype=torch.float64, requires_grad=True)
    bias = torch.tensor([1.5, 2.5], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda w: tonemap(image, "reinhard_luminance", white_point=w), (white,))
    assert torch.autograd.gradcheck(lambda w, b: tonemap(image, "hable", white_point=w, exposure_bias=b), (white, bias))


def test_per_sample_white_point_equals_separate_runs(device):
    image = torch.rand(3, 3, 4, 5, dtype=torch.float64, device=device) * 10
    white = torch.tensor([2.0, 4.0, 8.0], dtype=torch.float64, device=device)
    batched = tg.ToneMap("reinhard_extended", white_point=white)(image)
    for i in range(3):
        torch.testing.assert_close(batched[i : i + 1], tonemap(image[i : i + 1], "reinhard_extended", white_point=white[i].item()))


def test_learnable_white_point_is_a_parameter_and_gets_a_gradient(device):
    layer = tg.ToneMap("reinhard_extended", white_point=torch.nn.Parameter(torch.tensor(6.0))).to(device)
    assert [name for name, _ in layer.named_parameters()] == ["white_point"]
    layer(torch.rand(1, 3, 4, 4, device=device) * 5).sum().backward()
    assert layer.white_point.grad is not None and torch.isfinite(layer.white_point.grad)


EXTREME_VALUES = [0.0, 1e-45, 1e-8, 0.18, 59.9, 60.0, 65504.0, 1e30, 3e38, -1.0, -1e30]


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_extremes_give_finite_display_values_and_gradients(mode, device):
    grid = [[a, b, c] for a in EXTREME_VALUES for b in (0.0, 0.18, 1e30) for c in (0.0, 65504.0)]
    image = pixels(grid, torch.float32, device).requires_grad_()
    out = tonemap(image, mode)
    assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    out.sum().backward()
    assert torch.isfinite(image.grad).all()


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_nan_and_inf_pixels_do_not_spread(mode, device):
    image = torch.rand(1, 3, 4, 4, device=device) * 4
    image[0, :, 1, 1] = torch.tensor([float("nan"), float("inf"), -float("inf")])
    clean = image.clone()
    clean[0, :, 1, 1] = 0.5
    out, expected = tonemap(image, mode), tonemap(clean, mode)
    assert torch.isfinite(out).all()
    mask = torch.ones(4, 4, dtype=torch.bool, device=device)
    mask[1, 1] = False
    torch.testing.assert_close(out[..., mask], expected[..., mask])


@pytest.mark.parametrize("dtype, tolerance", [(torch.float16, 1e-3), (torch.bfloat16, 8e-3)])
@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_low_precision_inputs_work_without_overflow(mode, dtype, tolerance):
    image = torch.cat([torch.rand(1, 3, 8, 8) * 4, torch.full((1, 3, 1, 8), 1000.0)], dim=2).to(dtype)
    out = tonemap(image, mode)
    assert out.dtype == dtype and torch.isfinite(out).all()
    reference = tonemap(image.float(), mode)
    assert (out.float() - reference).abs().max() <= tolerance


@pytest.mark.parametrize(
    "image, error",
    [
        (torch.rand(1, 2, 4, 4), ValueError),
        (torch.rand(1, 5, 4, 4), ValueError),  # 4 channels are RGBA, taken
        (torch.ones(1, 3, 4, 4, dtype=torch.int32), TypeError),
        (torch.rand(1, 3, 0, 4), ValueError),
        (torch.rand(3, 4), ValueError),
    ],
)
def test_bad_images_raise_clear_errors(image, error):
    with pytest.raises(error):
        tg.ToneMap("aces")(image)


def test_bad_configuration_names_the_problem():
    with pytest.raises(ValueError, match="unknown tone mapping mode 'filmic2'"):
        tg.ToneMap("filmic2")
    with pytest.raises(ValueError, match="white_point"):
        tg.ToneMap("reinhard_extended", white_point=-1.0)
    with pytest.raises(ValueError, match="white_point"):
        tg.ToneMap("aces", white_point=3.0)


# --- the registry and the ToneMap stage


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_every_curve_clips_only_when_asked(mode):
    from torchgrade.tonemap import TONE_MAPPERS

    image = torch.exp(torch.randn(1, 3, 8, 8, dtype=torch.float64) * 3.0)
    curve = TONE_MAPPERS[mode].curve
    unclipped = curve(image, clip=False)
    assert torch.equal(curve(image), unclipped.clamp(0.0, 1.0))
    assert torch.equal(tonemap(image, mode, clip=False), unclipped)


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_stage_controls_are_the_mode_controls_and_round_trip(mode):
    from torchgrade.tonemap import TONE_MAPPERS

    layer = tg.ToneMap(mode, clip=False)
    assert list(layer.control_table()) == ["mode", "clip", *TONE_MAPPERS[mode].controls]
    assert layer.to_config() == {"mode": mode, "clip": False, **{name: c.default for name, c in TONE_MAPPERS[mode].controls.items()}}
    assert tg.ToneMap.from_config(layer.to_config()).to_config() == layer.to_config()
    assert layer.display_referred and not layer.is_identity and layer.expects_hdr == (mode != "none")


def test_signature_shows_every_curve_parameter():
    import inspect

    from torchgrade.tonemap import TONE_MAPPERS

    signature = inspect.signature(tg.ToneMap)
    assert list(signature.parameters)[:4] == ["mode", "white_point", "exposure_bias", "clip"]
    assert {name for entry in TONE_MAPPERS.values() for name in entry.controls} <= set(signature.parameters)


def test_assigning_a_mode_resets_the_curve_parameters_and_keeps_clip():
    layer = tg.ToneMap("unreal_filmic", slope=torch.nn.Parameter(torch.tensor(0.9)), clip=False)
    layer.mode = "reinhard_extended"
    assert layer.to_config() == {"mode": "reinhard_extended", "clip": False, "white_point": 4.0}
    assert list(layer.parameters()) == [] and not hasattr(layer, "slope")
    with pytest.raises(ValueError, match="unknown tone mapping mode 'filmic2'"):
        layer.mode = "filmic2"
    with pytest.raises(ValueError, match="white_point must lie in"):
        layer.white_point = 0.0
    assert layer.to_config() == {"mode": "reinhard_extended", "clip": False, "white_point": 4.0}


def test_a_learnable_parameter_moved_out_of_range_raises_at_forward():
    layer = tg.ToneMap("hable", exposure_bias=torch.nn.Parameter(torch.tensor(2.0)))
    with torch.no_grad():
        layer.exposure_bias.fill_(0.0)
    with pytest.raises(ValueError, match="exposure_bias must lie in"):
        layer(torch.rand(1, 3, 2, 2))
