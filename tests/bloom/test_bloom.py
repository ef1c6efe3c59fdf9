"""Bloom: light conservation, thresholding, firefly fading, upsampling, gradients, parameters, sizes."""

import inspect
import math

import pytest
import torch
import torch.nn.functional as F

import torchgrade as tg
from torchgrade.bloom import BLOOM_MODES
from torchgrade.bloom.pyramid import upsample

bloom = tg.functional.bloom


def relative_light_error(output: torch.Tensor, image: torch.Tensor) -> float:
    """|sum(out) - sum(in)| / sum(|in|), accumulated in float64."""
    return ((output.double().sum() - image.double().sum()).abs() / image.double().abs().sum()).item()


def unity_threshold(brightness: float, threshold_gamma: float, knee: float) -> float:
    """Unity's ApplyBloomThreshold for a grey pixel, written out from the shader and DoBloom."""
    x = ((threshold_gamma + 0.055) / 1.055) ** 2.4 if threshold_gamma > 0.04045 else threshold_gamma / 12.92
    y = x * knee
    z = 2.0 * y
    w = 0.25 / (y + 0.00001)
    soft = min(max(brightness + y - x, 0.0), z)
    soft = soft * soft * w
    contribution = max(soft, brightness - x)
    return brightness * contribution / max(brightness, 0.00001)


def bordered_image(height=37, width=29, device=None) -> torch.Tensor:
    """Dim noise with very bright corners, edge rows and edge columns: the worst case for border leaks."""
    image = torch.rand(1, 3, height, width, device=device) * 0.2
    image[..., 0, :] = 50.0
    image[..., :, -1] = 80.0
    image[..., [0, 0, -1, -1], [0, -1, 0, -1]] = 1000.0
    image[..., -1, 3:9] = 300.0
    return image


def read_rgb(exr_dir, name: str) -> torch.Tensor:
    return tg.io.read_exr(exr_dir / name)[:3].unsqueeze(0)


# --- light conservation (scattering) -------------------------------------------------------------


@pytest.mark.parametrize("fade_fireflies", [True, False])
@pytest.mark.parametrize("bicubic", [False, True])
@pytest.mark.parametrize("kind", ["random", "bordered"])
def test_scattering_conserves_light_synthetic(kind, bicubic, fade_fireflies, device):
    image = torch.rand(2, 3, 45, 31, device=device) * 20.0 if kind == "random" else bordered_image(device=device)
    out = bloom(
        image, mode="scattering", threshold=0.0, intensity=1.0, scatter=0.9,
        fade_fireflies=fade_fireflies, bicubic_upsampling=bicubic, downscale_limit=1,
    )
    assert relative_light_error(out, image) < 1e-3
    assert not torch.equal(out, image)  # light did move


@pytest.mark.parametrize("name", ["BrightRings.exr", "Desk.exr", "Garden.exr"])
def test_scattering_conserves_light_on_real_images(exr_dir, name):
    image = read_rgb(exr_dir, name)
    for threshold in (0.0, 1.0):
        out = bloom(image, mode="scattering", threshold=threshold, intensity=1.0, scatter=0.7)
        assert relative_light_error(out, image) < 1e-3, (name, threshold)


def test_scattering_conserves_light_per_sample_to_rounding(device):
    image = torch.rand(3, 3, 24, 40, dtype=torch.float64, device=device) * torch.tensor([1.0, 10.0, 1000.0], device=device).view(3, 1, 1, 1)
    out = bloom(image, mode="scattering", threshold=torch.tensor([0.0, 0.5, 1.0]), knee=0.3, scatter=0.3)  # a CPU control moves to the image
    torch.testing.assert_close(out.sum(dim=(1, 2, 3)), image.sum(dim=(1, 2, 3)), rtol=1e-12, atol=0)


def test_scattering_moves_light_away_from_a_bright_pixel():
    image = torch.full((1, 3, 32, 32), 0.1)
    image[..., 16, 16] = 100.0
    out = bloom(image, mode="scattering", threshold=0.0, intensity=0.5)
    assert out[..., 16, 16].max() < 100.0
    assert (out[..., 10, 16] > image[..., 10, 16]).all()
    assert (out >= 0).all()


def test_scattering_clamps_intensity_to_one():
    image = torch.rand(1, 3, 20, 20) * 5
    torch.testing.assert_close(bloom(image, mode="scattering", intensity=4.0), bloom(image, mode="scattering", intensity=1.0))


# --- threshold and additive mode ------------------------------------------------------------------


@pytest.mark.parametrize("threshold_gamma, knee", [(1.0, 0.5), (0.5, 0.5), (0.8, 0.0), (1.2, 1.0), (0.0, 0.5)])
def test_bloom_threshold_matches_unity_soft_knee(threshold_gamma, knee):
    values = [0.0, 0.01, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0, 1.2, 1.6, 3.0, 100.0]
    image = torch.tensor(values, dtype=torch.float64).view(1, -1, 1).expand(3, -1, 1)
    result = tg.functional.bloom_threshold(image, threshold=threshold_gamma, knee=knee)[0, :, 0]
    expected = torch.tensor([unity_threshold(v, threshold_gamma, knee) for v in values], dtype=torch.float64)
    torch.testing.assert_close(result, expected, rtol=1e-12, atol=1e-15)


def test_additive_below_the_knee_is_an_exact_identity():
    # linear threshold 1, knee 0.5: nothing below brightness 0.5 blooms
    image = torch.rand(2, 3, 33, 40) * 0.49
    out = bloom(image, mode="additive", threshold=1.0, knee=0.5, intensity=2.0)
    assert torch.equal(out, image)


def test_additive_adds_exactly_the_thresholded_light_per_level(device):
    image = torch.full((1, 3, 32, 32), 0.3, device=device)  # below the knee: contributes nothing
    image[..., 8:12, 8:12] = 5.0  # four whole 2x2 blocks; threshold 1 keeps 5 - 1 = 4 per channel
    out = bloom(image, mode="additive", threshold=1.0, knee=0.5, intensity=0.7, fade_fireflies=False)
    levels = 3  # 32 -> prefilter 16 -> levels of 8, 4, 2 (1 is below downscale_limit 2)
    thresholded_light = 16 * 3 * 4.0
    added = out.double().sum() - image.double().sum()
    assert added.item() == pytest.approx(0.7 * levels * thresholded_light, rel=1e-5)
    assert (out >= image).all()
    assert (out[..., 20, 20] > image[..., 20, 20]).all()  # the glow spreads beyond the bright block


def test_additive_glow_grows_with_intensity_and_threshold_lowers_it():
    image = torch.rand(1, 3, 40, 40) * 4
    glow = lambda **kw: (bloom(image, mode="additive", **kw) - image).sum().item()  # noqa: E731
    assert glow(intensity=2.0) == pytest.approx(2.0 * glow(intensity=1.0), rel=1e-5)
    assert glow(threshold=1.5) < glow(threshold=1.0) < glow(threshold=0.5)


# --- fireflies ------------------------------------------------------------------------------------


def test_firefly_fading_dims_a_single_pixel_but_not_a_broad_area():
    firefly = torch.zeros(1, 3, 64, 64)
    firefly[..., 31, 31] = 1000.0
    area = torch.zeros(1, 3, 64, 64)
    area[..., 16:48, 16:48] = 10.0

    def glow(image, fade):
        return (bloom(image, threshold=1.0, fade_fireflies=fade) - image).sum().item()

    assert glow(firefly, True) < 0.02 * glow(firefly, False)
    assert glow(area, True) > 0.7 * glow(area, False)


# --- upsampling -----------------------------------------------------------------------------------


def cubic_bspline(t: float) -> float:
    t = abs(t)
    if t < 1:
        return (4 - 6 * t**2 + 3 * t**3) / 6
    return (2 - t) ** 3 / 6 if t < 2 else 0.0


def test_bicubic_upsampling_is_the_cubic_bspline_away_from_borders():
    coarse = torch.rand(1, 1, 16, 16, dtype=torch.float64)
    fine = upsample(coarse, [(32, 32)], bicubic=True)
    # fine pixel i sits at coarse coordinate (i + 0.5) / 2 - 0.5
    taps = range(-3, 4)
    expected = torch.zeros(32, 32, dtype=torch.float64)
    for i in range(8, 24):
        for j in range(8, 24):
            u, v = (i + 0.5) / 2 - 0.5, (j + 0.5) / 2 - 0.5
            for a in taps:
                for b in taps:
                    expected[i, j] += cubic_bspline(u - (math.floor(u) + a)) * cubic_bspline(v - (math.floor(v) + b)) * coarse[0, 0, math.floor(u) + a, math.floor(v) + b]
    torch.testing.assert_close(fine[0, 0, 8:24, 8:24], expected[8:24, 8:24], rtol=1e-12, atol=1e-12)


def test_bilinear_upsampling_is_torch_bilinear_away_from_borders():
    coarse = torch.rand(1, 3, 9, 7, dtype=torch.float64)
    fine = upsample(coarse, [(18, 14)], bicubic=False)
    reference = F.interpolate(coarse, scale_factor=2, mode="bilinear", align_corners=False)
    torch.testing.assert_close(fine[..., 1:-1, 1:-1], reference[..., 1:-1, 1:-1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("mode", ["additive", "scattering"])
def test_upsampling_never_makes_negative_light_on_bright_rings(exr_dir, mode):
    image = read_rgb(exr_dir, "BrightRings.exr")
    glows = {}
    for bicubic in (False, True):
        out = bloom(image, mode=mode, threshold=1.0, intensity=1.0, bicubic_upsampling=bicubic)
        assert (out >= 0).all()
        if mode == "additive":
            assert (out >= image).all()  # the glow is nowhere negative
        glows[bicubic] = (out - image).double()
    # both keep the same light; the B-spline is at least as smooth (total variation of the glow)
    if mode == "additive":
        assert glows[True].sum().item() == pytest.approx(glows[False].sum().item(), rel=1e-4)

    def variation(g):
        return (g.diff(dim=-1).abs().sum() + g.diff(dim=-2).abs().sum()).item()

    assert variation(glows[True]) <= variation(glows[False])


def test_keys_bicubic_would_make_negative_light_on_bright_rings(exr_dir):
    """Why the B-spline: PyTorch's (Keys) bicubic overshoots next to the rings' sharp edges."""
    bright = tg.functional.bloom_threshold(read_rgb(exr_dir, "BrightRings.exr"), threshold=1.0)
    assert (bright >= 0).all()
    assert (F.interpolate(bright, scale_factor=2, mode="bicubic", align_corners=False) < 0).any()


# --- gradients ------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["additive", "scattering"])
def test_gradcheck(mode):
    image = (torch.rand(2, 3, 8, 12, dtype=torch.float64) * 3 + 0.2).requires_grad_()
    threshold = torch.tensor([0.8, 0.6], dtype=torch.float64, requires_grad=True)
    knee = torch.tensor(0.5, dtype=torch.float64, requires_grad=True)
    intensity = torch.tensor([0.7, 0.4], dtype=torch.float64, requires_grad=True)
    scatter = torch.tensor(0.6, dtype=torch.float64, requires_grad=True)

    def function(image, threshold, knee, intensity, scatter):
        return bloom(image, mode=mode, threshold=threshold, knee=knee, intensity=intensity,
                     scatter=scatter, downscale_limit=1, bicubic_upsampling=mode == "scattering")

    inputs = (image, threshold, knee, intensity, scatter) if mode == "scattering" else (image, threshold, knee, intensity)
    assert torch.autograd.gradcheck(function if mode == "scattering" else lambda *a: function(*a, scatter), inputs, fast_mode=True)


def test_gradients_are_finite_at_extremes():
    image = torch.tensor([0.0, 0.18, 60.0, 65504.0, 1e30, -1.0]).repeat(3, 16, 4).unsqueeze(0)
    for mode in ("additive", "scattering"):
        leaves = [image.clone().requires_grad_()] + [torch.tensor(v, requires_grad=True) for v in (0.0, 0.0, 1.0, 0.5)]
        out = bloom(leaves[0], mode=mode, threshold=leaves[1], knee=leaves[2], intensity=leaves[3], scatter=leaves[4])
        out.sum().backward()
        assert torch.isfinite(out).all()
        used = leaves if mode == "scattering" else leaves[:4]
        assert all(leaf.grad is not None and torch.isfinite(leaf.grad).all() for leaf in used)


@pytest.mark.parametrize("source", [dict(clamp=100.0), dict(karis_average=True), dict(clamp=100.0, karis_average=True)])
@pytest.mark.parametrize("mode", BLOOM_MODES)
def test_gradients_are_finite_where_a_block_holds_denormal_light(mode, source):
    """A block with a channel at 1e-40 (whose square underflows float32): the block's share of its light divided by a
    mean of 1e-40 in the branch a select discards, and its infinite gradient times 0 was NaN (scattering bloom)."""
    image = torch.tensor([1e-40, 1e-45, 0.0, 60.0]).repeat(3, 8, 2).unsqueeze(0)
    image[:, 1] = 1e-38
    image.requires_grad_()
    out = tg.Bloom(mode=mode, intensity=0.5, **source)(image)
    out.sum().backward()
    assert torch.isfinite(out).all() and torch.isfinite(image.grad).all()


# --- parameters and module ------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["additive", "scattering"])
def test_per_sample_parameters_match_separate_calls(mode):
    image = torch.rand(3, 3, 26, 34) * 4
    values = {"threshold": [0.5, 1.0, 1.5], "knee": [0.0, 0.5, 1.0], "intensity": [0.2, 0.9, 3.0], "scatter": [0.1, 0.5, 0.9]}
    batched = bloom(image, mode=mode, **{k: torch.tensor(v) for k, v in values.items()})
    for i in range(3):
        single = bloom(image[i : i + 1], mode=mode, **{k: v[i] for k, v in values.items()})
        torch.testing.assert_close(batched[i : i + 1], single)


def test_module_registers_parameters_buffers_and_numbers():
    threshold = torch.nn.Parameter(torch.tensor(0.9))
    module = tg.Bloom(mode="scattering", threshold=threshold, knee=torch.tensor([0.5, 0.2]), intensity=0.5)
    assert any(p is threshold for p in module.parameters())
    assert "knee" in dict(module.named_buffers())
    assert module.intensity == 0.5 and isinstance(module.intensity, float)
    assert module.to_config() == {
        "mode": "scattering", "threshold": pytest.approx(0.9), "knee": [0.5, pytest.approx(0.2)], "intensity": 0.5,
        "scatter": 0.7, "max_iterations": 16, "downscale_limit": 2, "fade_fireflies": True, "bicubic_upsampling": False,
    }
    image = torch.rand(2, 3, 16, 16) * 3
    out = module(image)
    out.sum().backward()
    assert threshold.grad is not None and torch.isfinite(threshold.grad)
    expected = bloom(image, mode="scattering", threshold=0.9, knee=torch.tensor([0.5, 0.2]), intensity=0.5)
    torch.testing.assert_close(out, expected)


def test_default_module_matches_the_contract():
    assert tg.Bloom().to_config() == {
        "mode": "additive", "threshold": 1.0, "knee": 0.5, "intensity": 1.0, "scatter": 0.7,
        "max_iterations": 16, "downscale_limit": 2, "fade_fireflies": True, "bicubic_upsampling": False,
    }


@pytest.mark.parametrize(
    "arguments, name",
    [
        ({"mode": "glow"}, "mode"),
        ({"threshold": -0.1}, "threshold"),
        ({"knee": 1.5}, "knee"),
        ({"intensity": -1.0}, "intensity"),
        ({"scatter": 0.99}, "scatter"),
        ({"scatter": torch.tensor([0.5, 0.01])}, "scatter"),
        ({"max_iterations": -1}, "max_iterations"),
        ({"max_iterations": 2.5}, "max_iterations"),
        ({"max_iterations": 17}, "max_iterations"),
        ({"downscale_limit": 0}, "downscale_limit"),
    ],
)
def test_invalid_parameters_raise_naming_the_parameter(arguments, name):
    with pytest.raises(ValueError, match=name):
        tg.Bloom(**arguments)
    if any(isinstance(value, torch.Tensor) for value in arguments.values()):
        return  # the functional door reads no tensor back (a wait on a GPU), as every door (controls.check_given)
    with pytest.raises(ValueError, match=name):
        bloom(torch.rand(1, 3, 8, 8), **arguments)


def test_functional_and_stage_take_exactly_the_control_table():
    names = list(tg.bloom.CONTROLS)
    assert list(inspect.signature(tg.Bloom).parameters) == names
    assert list(inspect.signature(bloom).parameters) == ["image", *names, "fixed_depth"]
    with pytest.raises(TypeError, match="treshold"):
        bloom(torch.rand(1, 3, 8, 8), treshold=1.0)
    with pytest.raises(ValueError, match="treshold"):
        tg.Bloom(treshold=1.0)
    # a truthy flag is the same flag in both, as it was before either checked it
    image = torch.rand(1, 3, 16, 16) * 4
    assert torch.equal(bloom(image, fade_fireflies=0), bloom(image, fade_fireflies=False))
    assert tg.Bloom(karis_average=1).karis_average is True


def test_bad_images_raise():
    with pytest.raises(TypeError):
        bloom(torch.zeros(1, 3, 8, 8, dtype=torch.int32))
    with pytest.raises(ValueError):
        bloom(torch.zeros(1, 4, 8, 8))
    with pytest.raises(ValueError, match="per-sample"):
        bloom(torch.rand(2, 3, 16, 16), intensity=torch.tensor([1.0, 1.0, 1.0]))


# --- identity elision -----------------------------------------------------------------------------


def test_identities_return_the_input_untouched():
    image = torch.rand(2, 3, 16, 16) * 5
    assert bloom(image, intensity=0.0) is image
    assert torch.equal(bloom(image, mode="scattering", intensity=torch.tensor(0.0)), image)  # a tensor's is computed
    assert bloom(image, max_iterations=0) is image
    assert tg.Bloom(intensity=0)(image) is image
    dark = torch.rand(1, 3, 16, 16) * 0.4
    assert torch.equal(bloom(dark, mode="scattering", threshold=1.0), dark)


def test_learnable_zero_intensity_is_computed_and_differentiable():
    intensity = torch.nn.Parameter(torch.tensor(0.0))
    image = torch.rand(1, 3, 16, 16) * 5
    out = tg.Bloom(intensity=intensity)(image)
    assert torch.equal(out, image)
    out.sum().backward()
    assert intensity.grad > 0


# --- sizes, dtypes, non-finite input --------------------------------------------------------------


@pytest.mark.parametrize("size", [(1, 1), (2, 2), (7, 5), (3, 9), (5, 64), (33, 17), (67, 45)])
def test_sizes_including_odd_and_tiny(size, device):
    image = torch.rand(1, 3, *size, device=device) * 10
    for mode in ("additive", "scattering"):
        out = bloom(image, mode=mode, threshold=0.5)
        assert out.shape == image.shape and torch.isfinite(out).all()
        if mode == "scattering":
            assert relative_light_error(out, image) < 1e-5
    if min(size) < 8:  # the quarter-resolution level would be smaller than downscale_limit: no bloom
        assert bloom(image, threshold=0.5) is image


def test_unbatched_and_extra_leading_dimensions():
    image = torch.rand(2, 2, 3, 20, 24) * 4
    out = bloom(image, mode="scattering", threshold=0.0)
    assert out.shape == image.shape
    torch.testing.assert_close(out[1, 0], bloom(image[1, 0], mode="scattering", threshold=0.0))


def test_4k_frame():
    image = torch.rand(1, 3, 2160, 3840) * 2
    with torch.no_grad():
        out = bloom(image, mode="scattering", threshold=1.0)
    assert out.shape == image.shape
    assert relative_light_error(out, image) < 1e-3


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_half_precision_is_computed_in_float32(dtype):
    image = torch.rand(1, 3, 32, 32) * 100
    image[..., 5, 5] = 60000.0
    out = bloom(image.to(dtype), intensity=4.0)
    assert out.dtype == dtype and torch.isfinite(out).all()
    reference = bloom(image.to(dtype).float(), intensity=4.0)
    torch.testing.assert_close(out.float(), reference.clamp(max=65504.0).to(dtype).float())


def test_non_finite_pixels_follow_the_sanitize_policy(exr_dir, device):
    image = read_rgb(exr_dir, "BrightRingsNanInf.exr").to(device)
    assert torch.isnan(image).any() and torch.isinf(image).any()
    cleaned = torch.nan_to_num(image, nan=0.0, posinf=65504.0, neginf=-65504.0)
    for mode in ("additive", "scattering"):
        out = bloom(image, mode=mode, threshold=1.0)
        assert torch.isfinite(out).all()
        assert torch.equal(out, bloom(cleaned, mode=mode, threshold=1.0))
    # one NaN pixel in a smooth frame counts as a black pixel: only a trace of it reaches other pixels
    frame = torch.full((1, 3, 40, 40), 2.0, device=device)
    broken, black = frame.clone(), frame.clone()
    broken[..., 20, 20] = float("nan")
    black[..., 20, 20] = 0.0
    out = bloom(broken)
    assert torch.equal(out, bloom(black))
    elsewhere = torch.ones(40, 40, dtype=torch.bool, device=device)
    elsewhere[20, 20] = False
    assert ((out - bloom(frame))[..., elsewhere].abs() < 0.05).all()


# --- the stage ------------------------------------------------------------------------------------


def test_stage_identity_assignment_and_table():
    assert tg.Bloom(max_iterations=0).is_identity and tg.Bloom(intensity=0).is_identity
    assert not tg.Bloom().is_identity
    assert not tg.Bloom(intensity=torch.nn.Parameter(torch.tensor(0.0))).is_identity
    stage = tg.Bloom()
    with pytest.raises(ValueError, match="scatter"):
        stage.scatter = 0.99
    with pytest.raises(ValueError, match="mode"):
        stage.mode = "glow"
    stage.intensity = 2
    assert stage.intensity == 2.0 and isinstance(stage.intensity, float)
    assert tg.Bloom.controls["scatter"].range == (0.05, 0.95)
    assert tg.Bloom.controls["mode"].range == tg.bloom.BLOOM_MODES


def test_learnable_control_moved_out_of_range_raises_at_forward():
    scatter = torch.nn.Parameter(torch.tensor(0.5))
    stage = tg.Bloom(mode="scattering", scatter=scatter)
    with torch.no_grad():
        scatter.fill_(2.0)
    with pytest.raises(ValueError, match="scatter"):
        stage(torch.rand(1, 3, 16, 16))


@pytest.mark.parametrize("mode", tg.bloom.BLOOM_MODES)
def test_zero_is_identity_says_which_blends_keep_the_image_at_intensity_zero(mode):
    composite = tg.bloom.COMPOSITES[mode]
    image = torch.tensor([-1.0, 0.0, 0.1, 0.25, 0.7, 1.0, 3.0, 65504.0]).reshape(1, 1, 2, 4)
    kept = torch.ones_like(image) if composite.scatters else None  # 1 - strength * fraction at strength 0
    out = composite.blend(image, torch.zeros_like(image), torch.tensor(0.0), kept)
    assert torch.equal(out, image) == composite.zero_is_identity


@pytest.mark.parametrize("mode", tg.bloom.BLOOM_MODES)
@pytest.mark.parametrize("size", [(5, 7), (7, 300)])
def test_fixed_depth_form_leaves_a_frame_too_small_for_any_level_unchanged(mode, size):
    image = torch.rand(1, 3, *size) * 4
    assert torch.equal(bloom(image, mode=mode, threshold=0.2, fixed_depth=6), image)
