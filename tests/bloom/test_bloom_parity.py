"""Engine-parity bloom options: Bevy's energy-conserving composite, Godot's blend modes, Karis average, clamp,
tint, lens dirt, anamorphic ratio and the FFT convolution bloom, each against a reference written here."""

import json
import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

import torchgrade as tg
from torchgrade.bloom.composite import bevy_blend_factor
from torchgrade.bloom.convolution import direct_convolve
from torchgrade.bloom.layer import OPTION_DEFAULTS
from torchgrade.bloom.prefilter import karis_mean
from torchgrade.bloom.blur import anamorphic_sigma

bloom = tg.functional.bloom


def hdr(shape, seed=0, dtype=torch.float32) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(shape, generator=generator, dtype=torch.float64) ** 3 * 12.0 + 0.01).to(dtype)


def relative_light_error(output, image) -> float:
    return ((output.double().sum() - image.double().sum()).abs() / image.double().abs().sum()).item()


def srgb_decode(c: float) -> float:
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def additive_glow(image, **options):
    """``intensity * tint * glow`` at full resolution, as additive mode adds it."""
    return bloom(image, mode="additive", **options) - image


# --- Bevy: energy-conserving composite ------------------------------------------------------------


@pytest.mark.parametrize("mip, max_mip", [(0, 4), (1, 4), (3, 4), (4, 4), (2, 7)])
@pytest.mark.parametrize("intensity, boost, curvature, high_pass", [(0.15, 0.7, 0.95, 1.0), (0.4, 0.3, 0.5, 0.6), (1.0, 1.0, 0.0, 0.2)])
def test_bevy_blend_factor_matches_the_published_formula(mip, max_mip, intensity, boost, curvature, high_pass):
    x = mip / max_mip
    lf_boost = (1 - (1 - x) ** (1 / (1 - curvature))) * boost * (1 - intensity)
    high_pass_lq = 1 - min(max((x - high_pass) / high_pass, 0.0), 1.0)
    expected = (intensity + lf_boost) * high_pass_lq
    as_tensor = lambda v: torch.tensor(v, dtype=torch.float64)  # noqa: E731
    result = bevy_blend_factor(mip, max_mip, *(as_tensor(v) for v in (intensity, boost, curvature, high_pass)))
    assert result.item() == pytest.approx(expected, rel=1e-12, abs=1e-15)


def test_energy_conserving_without_boost_is_scattering_with_scatter_equal_to_intensity():
    image = hdr((2, 3, 40, 56), dtype=torch.float64)
    common = dict(threshold=0.0, fade_fireflies=False, intensity=0.35)
    energy = bloom(image, mode="energy_conserving", low_frequency_boost=0.0, high_pass_frequency=1.0, **common)
    scattering = bloom(image, mode="scattering", scatter=0.35, **common)
    torch.testing.assert_close(energy, scattering, rtol=1e-12, atol=1e-12)


def test_energy_conserving_uses_bevys_factor_between_two_levels():
    """Two levels: the one blend factor is Bevy's at mip 1 of 1, ``intensity + boost * (1 - intensity)``."""
    image = hdr((1, 3, 32, 48), dtype=torch.float64)
    common = dict(threshold=0.0, fade_fireflies=False, intensity=0.3, max_iterations=2)
    energy = bloom(image, mode="energy_conserving", low_frequency_boost=0.5, low_frequency_boost_curvature=0.6, **common)
    scattering = bloom(image, mode="scattering", scatter=0.3 + 0.5 * (1 - 0.3), **common)
    torch.testing.assert_close(energy, scattering, rtol=1e-12, atol=1e-12)


def test_energy_conserving_conserves_light_when_the_prefilter_passes_all_of_it():
    image = hdr((2, 3, 45, 31))
    out = bloom(image, mode="energy_conserving", threshold=0.0, fade_fireflies=False, intensity=0.6,
                low_frequency_boost=0.9, low_frequency_boost_curvature=0.5, high_pass_frequency=0.5)
    assert relative_light_error(out, image) < 1e-5
    assert not torch.equal(out, image)
    # with a threshold it darkens by intensity times the light the threshold held back (Bevy's behaviour)
    thresholded = bloom(image, mode="energy_conserving", threshold=1.0, intensity=0.6)
    assert thresholded.double().sum() < image.double().sum()


# --- Godot: glow blend modes -----------------------------------------------------------------------


def godot_softlight(c: float, g: float) -> float:
    """Godot 4.0's per-channel soft light on glow mapped to [0.5, 1]; colours above 1 kept (as Godot 4.3+)."""
    if c > 1.0:
        return c
    g = min(max(g, 0.0), 1.0) * 0.5 + 0.5
    if g <= 0.5:
        return c - (1 - 2 * g) * c * (1 - c)
    if c <= 0.25:
        return c + (2 * g - 1) * (4 * c * (4 * c + 1) * (c - 1) + 7 * c)
    return c + (2 * g - 1) * (math.sqrt(c) - c)


GODOT_BLENDS = {
    "screen": lambda c, g, i: c + min(max(g, 0.0), 1.0) - c * min(max(g, 0.0), 1.0),
    "softlight": lambda c, g, i: godot_softlight(c, g),
    "replace": lambda c, g, i: g,
    "mix": lambda c, g, i: c * (1 - i) + g,
}


@pytest.mark.parametrize("mode", list(GODOT_BLENDS))
def test_godot_blend_modes_match_per_pixel_references(mode):
    image = hdr((1, 3, 20, 24), dtype=torch.float64) * 0.25  # colours on both sides of 0.25 and 1
    intensity = 0.7
    glow = additive_glow(image, intensity=intensity, threshold=0.3, knee=0.7)
    out = bloom(image, mode=mode, intensity=intensity, threshold=0.3, knee=0.7).numpy()
    blend = np.vectorize(lambda c, g: GODOT_BLENDS[mode](c, g, intensity))
    np.testing.assert_allclose(out, blend(image.numpy(), glow.numpy()), rtol=1e-9, atol=1e-12)
    assert (image > 1).any() and (image < 0.25).any() and (glow > 0.05).any()


# --- Karis average and clamp ----------------------------------------------------------------------


def overlaps(side: int) -> np.ndarray:
    """``(ceil(side / 2), side)``: the length of fine pixel ``j`` inside coarse pixel ``i`` when ``ceil(side / 2)``
    equal pixels span the side (interval arithmetic in fractions of a fine pixel)."""
    half = -(-side // 2)
    start = np.arange(half)[:, None] * side / half
    stop = start + side / half
    j = np.arange(side)[None, :]
    return np.clip(np.minimum(stop, j + 1) - np.maximum(start, j), 0.0, None)


@pytest.mark.parametrize("height, width", [(7, 9), (8, 6)])
def test_karis_mean_matches_a_per_block_reference(height, width):
    """Karis' 1/(1+Y)-weighted mean over each half-resolution pixel's footprint (whole pixels at even sides,
    parts of pixels at odd ones, by the area they share), capped at the plain mean."""
    image = hdr((1, 3, height, width), dtype=torch.float64)
    pixels = image[0].numpy()
    rows, columns = overlaps(height), overlaps(width)
    area = rows[:, :, None, None] * columns[None, None, :, :]  # (i, y, j, x)
    luma = 0.2126729 * pixels[0] + 0.7151522 * pixels[1] + 0.0721750 * pixels[2]
    weights = 1.0 / (1.0 + luma)
    weighted = np.einsum("iyjx,cyx->cij", area, pixels * weights) / np.einsum("iyjx,yx->ij", area, weights)
    means = np.einsum("iyjx,cyx->cij", area, pixels) / area.sum(axis=(1, 3))
    result = karis_mean(image, torch.from_numpy(means)[None])
    np.testing.assert_allclose(result[0].numpy(), np.minimum(weighted, means), rtol=1e-12)


def test_karis_average_dims_a_lone_hot_pixel_and_keeps_light_exact():
    image = torch.full((1, 3, 32, 32), 0.2)
    image[..., 15, 15] = 500.0
    glow = lambda **kw: additive_glow(image, fade_fireflies=False, **kw).sum().item()  # noqa: E731
    assert glow(karis_average=True) < 0.05 * glow()
    colourful = hdr((2, 3, 37, 29))
    colourful[:, 2, ::2, ::2] *= 20.0  # blue brighter in dim pixels: the cap binds
    for fade in (True, False):
        out = bloom(colourful, mode="scattering", threshold=0.5, karis_average=True, fade_fireflies=fade, intensity=1.0)
        assert relative_light_error(out, colourful) < 1e-5
        assert (out >= 0).all()


def test_clamp_bounds_the_bloom_source_not_the_image():
    blocks = F.interpolate(hdr((1, 3, 16, 20), dtype=torch.float64) * 5, scale_factor=2, mode="nearest")
    bound = 3.0
    clamped_glow = additive_glow(blocks, clamp=bound, fade_fireflies=False)
    expected = additive_glow(blocks.clamp(max=bound), fade_fireflies=False)
    torch.testing.assert_close(clamped_glow, expected, rtol=1e-12, atol=1e-12)
    assert torch.equal(bloom(blocks, clamp=1e6), bloom(blocks))
    out = bloom(blocks, mode="scattering", clamp=bound, threshold=0.2)
    assert relative_light_error(out, blocks) < 1e-12 and (out >= 0).all()


# --- tint, dirt, anamorphic ------------------------------------------------------------------------


def test_tint_multiplies_the_glow_by_the_decoded_colour_per_sample():
    image = hdr((2, 3, 24, 32), dtype=torch.float64)
    tints = [(1.0, 0.5, 0.2), (0.3, 0.9, 1.0)]
    out = additive_glow(image, tint=torch.tensor(tints, dtype=torch.float64))
    plain = additive_glow(image)
    for sample, tint in enumerate(tints):
        linear = torch.tensor([srgb_decode(c) for c in tint], dtype=torch.float64).view(3, 1, 1)
        torch.testing.assert_close(out[sample], plain[sample] * linear, rtol=1e-12, atol=1e-12)


def bilinear_resize(texture: np.ndarray, height: int, width: int) -> np.ndarray:
    """Half-pixel-centre bilinear resampling with clamped edges, per channel."""
    channels, h, w = texture.shape

    def taps(size, source):
        position = np.clip((np.arange(size) + 0.5) * source / size - 0.5, 0, source - 1)
        low = np.floor(position).astype(int)
        return low, np.minimum(low + 1, source - 1), position - low

    y0, y1, fy = taps(height, h)
    x0, x1, fx = taps(width, w)
    top = texture[:, y0][:, :, x0] * (1 - fx) + texture[:, y0][:, :, x1] * fx
    bottom = texture[:, y1][:, :, x0] * (1 - fx) + texture[:, y1][:, :, x1] * fx
    return top * (1 - fy)[:, None] + bottom * fy[:, None]


@pytest.mark.parametrize("mode", ["additive", "scattering", "screen"])
def test_lens_dirt_adds_dirt_times_the_full_resolution_glow(mode):
    image = hdr((1, 3, 30, 44), dtype=torch.float64)
    dirt = torch.rand(3, 7, 5, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    common = dict(threshold=0.0, fade_fireflies=False, intensity=1.0)  # scattering then outputs its glow alone
    out = bloom(image, mode=mode, dirt=dirt, dirt_intensity=2.5, **common)
    glow = bloom(image, mode="scattering", **common) if mode == "scattering" else additive_glow(image, **common)
    expected = bloom(image, mode=mode, **common) + 2.5 * torch.from_numpy(bilinear_resize(dirt.numpy(), 30, 44)) * glow
    torch.testing.assert_close(out, expected, rtol=1e-10, atol=1e-10)
    assert torch.equal(bloom(image, mode=mode, dirt=dirt, dirt_intensity=0.0), bloom(image, mode=mode))


def test_anamorphic_ratio_stretches_the_glow_along_the_chosen_axis():
    torch.testing.assert_close(anamorphic_sigma(torch.tensor(0.5)), torch.tensor([[1.69 / 2**0.5, 1.69 * 2**0.5]]))
    image = torch.zeros(1, 3, 64, 64)
    image[..., 31:33, 31:33] = 100.0
    glow = additive_glow(image, anamorphic_ratio=0.8)[0, 0].double()
    offsets = torch.arange(64, dtype=torch.float64) - 31.5
    variance_y = (glow.sum(1) * offsets**2).sum() / glow.sum()
    variance_x = (glow.sum(0) * offsets**2).sum() / glow.sum()
    assert variance_x > 1.5 * variance_y
    # a negative ratio is the transposed stretch
    frame = hdr((1, 3, 40, 40))
    torch.testing.assert_close(bloom(frame.transpose(-1, -2), anamorphic_ratio=-0.6),
                               bloom(frame, anamorphic_ratio=0.6).transpose(-1, -2), rtol=1e-5, atol=1e-5)
    out = bloom(frame, mode="scattering", anamorphic_ratio=-1.0, threshold=0.0, downscale_limit=1)
    assert relative_light_error(out, frame) < 1e-5


# --- FFT convolution bloom ---------------------------------------------------------------------------


def test_fft_convolution_bloom_matches_direct_conv2d_over_the_mirrored_frame():
    """The thresholded frame extended by its mirror image about the edge (NumPy's ``symmetric`` padding), convolved."""
    generator = torch.Generator().manual_seed(5)
    image = hdr((2, 3, 13, 17), dtype=torch.float64)
    kernel = torch.rand(3, 7, 5, dtype=torch.float64, generator=generator)
    out = tg.functional.convolution_bloom(image, kernel, threshold=0.8, knee=0.3, intensity=torch.tensor([0.5, 2.0], dtype=torch.float64))
    normalised = kernel / kernel.sum(dim=(-2, -1), keepdim=True)
    bright = tg.functional.bloom_threshold(image, threshold=0.8, knee=0.3)
    mirrored = torch.from_numpy(np.pad(bright.numpy(), ((0, 0), (0, 0), (3, 3), (2, 2)), mode="symmetric"))
    direct = F.conv2d(mirrored, normalised.flip(-2, -1).unsqueeze(1), groups=3)
    expected = image + torch.tensor([0.5, 2.0], dtype=torch.float64).view(2, 1, 1, 1) * direct
    torch.testing.assert_close(out, expected, rtol=1e-10, atol=1e-10)


def test_a_point_light_becomes_the_kernel_image():
    kernel = torch.zeros(1, 5, 5, dtype=torch.float64)
    kernel[0, 0, 4], kernel[0, 2, 2] = 3.0, 1.0  # asymmetric: a flipped kernel would show
    image = torch.zeros(1, 3, 11, 11, dtype=torch.float64)
    image[..., 5, 5] = 8.0
    glow = tg.ConvolutionBloom(kernel, threshold=0.0, knee=0.0)(image) - image
    assert glow[0, 0, 3, 7].item() == pytest.approx(6.0) and glow[0, 0, 5, 5].item() == pytest.approx(2.0)
    assert glow.abs().sum().item() == pytest.approx(3 * 8.0)


def test_convolution_bloom_identity_gradients_and_config():
    image = (torch.rand(1, 3, 6, 7, dtype=torch.float64) * 3).requires_grad_()
    kernel = (torch.rand(1, 3, 3, dtype=torch.float64) + 0.1).requires_grad_()
    intensity = torch.tensor(0.7, dtype=torch.float64, requires_grad=True)
    function = lambda i, k, s: tg.functional.convolution_bloom(i, k, threshold=0.5, intensity=s)  # noqa: E731
    assert torch.autograd.gradcheck(function, (image, kernel, intensity), fast_mode=True)
    plain = torch.rand(1, 3, 8, 8)
    assert tg.ConvolutionBloom(torch.ones(1, 3, 3), intensity=0.0)(plain) is plain
    module = tg.ConvolutionBloom(torch.ones(1, 3, 3), intensity=0.5)
    assert tg.ConvolutionBloom(**json.loads(json.dumps(module.to_config()))).to_config() == module.to_config()
    with pytest.raises(ValueError, match="odd"):
        tg.ConvolutionBloom(torch.ones(1, 4, 3))


# --- the library's rules: gradients, per-sample, validation, config, ONNX ---------------------------


GRADCHECK_CASES = {
    "energy_conserving": ("energy_conserving", ("intensity", "low_frequency_boost", "low_frequency_boost_curvature", "high_pass_frequency")),
    "screen": ("screen", ("intensity",)),
    "softlight": ("softlight", ("intensity",)),
    "mix": ("mix", ("intensity",)),
    "replace": ("replace", ("intensity",)),
    "options": ("additive", ("tint", "clamp", "anamorphic_ratio", "dirt_intensity")),
}
VALUES = {"intensity": [0.6, 0.3], "low_frequency_boost": 0.6, "low_frequency_boost_curvature": 0.5,
          "high_pass_frequency": 0.7, "tint": [[1.0, 0.6, 0.3], [0.5, 0.5, 1.0]], "clamp": [2.0, 3.0],
          "anamorphic_ratio": [0.5, -0.3], "dirt_intensity": 0.8}


@pytest.mark.parametrize("case", list(GRADCHECK_CASES))
def test_gradcheck(case):
    mode, names = GRADCHECK_CASES[case]
    image = (torch.rand(2, 3, 8, 12, dtype=torch.float64, generator=torch.Generator().manual_seed(2)) * 3 + 0.05).requires_grad_()
    leaves = [torch.tensor(VALUES[name], dtype=torch.float64, requires_grad=True) for name in names]
    extra = {"dirt": torch.rand(3, 4, 4, dtype=torch.float64), "karis_average": True} if case == "options" else {}

    def function(image, *values):
        return bloom(image, mode=mode, threshold=0.6, downscale_limit=1, **extra, **dict(zip(names, values)))

    assert torch.autograd.gradcheck(function, (image, *leaves), fast_mode=True)


def test_per_sample_options_match_separate_calls():
    image = hdr((2, 3, 26, 34))
    values = {"intensity": [0.2, 0.9], "clamp": [2.0, 50.0], "anamorphic_ratio": [-0.5, 0.7], "dirt_intensity": [0.0, 1.5],
              "low_frequency_boost": [0.1, 0.9], "high_pass_frequency": [0.3, 1.0]}
    dirt = torch.rand(3, 5, 6)
    batched = bloom(image, mode="energy_conserving", dirt=dirt, **{k: torch.tensor(v) for k, v in values.items()})
    for i in range(2):
        single = bloom(image[i : i + 1], mode="energy_conserving", dirt=dirt, **{k: v[i] for k, v in values.items()})
        torch.testing.assert_close(batched[i : i + 1], single)


@pytest.mark.parametrize("arguments, name", [
    ({"mode": "overlay"}, "mode"), ({"tint": (1.0, -0.1, 1.0)}, "tint"), ({"clamp": -1.0}, "clamp"),
    ({"anamorphic_ratio": 1.5}, "anamorphic_ratio"), ({"dirt_intensity": -1.0}, "dirt_intensity"),
    ({"low_frequency_boost": 1.2}, "low_frequency_boost"), ({"low_frequency_boost_curvature": 1.0}, "low_frequency_boost_curvature"),
    ({"high_pass_frequency": 0.0}, "high_pass_frequency"), ({"dirt": torch.rand(2, 4, 4)}, "dirt"),
])
def test_invalid_options_raise_naming_the_option(arguments, name):
    with pytest.raises(ValueError, match=name):
        tg.Bloom(**arguments)
    with pytest.raises(ValueError, match=name):
        bloom(torch.rand(1, 3, 16, 16), **arguments)


OPTIONS = dict(mode="energy_conserving", intensity=0.5, max_iterations=3, tint=(1.0, 0.8, 0.6), clamp=20.0,
               anamorphic_ratio=0.4, karis_average=True, dirt_intensity=0.7, low_frequency_boost=0.5,
               low_frequency_boost_curvature=0.8, high_pass_frequency=0.8)


def test_defaults_are_bit_identical_and_options_round_trip_through_configs():
    image = hdr((1, 3, 32, 40))
    assert torch.equal(tg.Bloom(**OPTION_DEFAULTS)(image), tg.Bloom()(image))
    assert tg.Bloom(**OPTION_DEFAULTS).to_config() == tg.Bloom().to_config()
    dirt = torch.rand(3, 6, 8)
    module = tg.Bloom(dirt=dirt, **OPTIONS)
    config = json.loads(json.dumps(module.to_config()))
    assert config["tint"] == [1.0, 0.8, 0.6] and len(config["dirt"]) == 3
    torch.testing.assert_close(tg.Bloom(**config)(image), module(image))
    look = tg.PostFX.from_config({"bloom": config, "tonemap": "neutral"})
    torch.testing.assert_close(look(image), tg.ToneMap("neutral")(module(image)))
    assert tg.PostFX(bloom=module).to_config()["bloom"] == config


def test_direct_convolution_equals_the_fft_one():
    light = torch.rand(2, 3, 11, 17, dtype=torch.float64)
    kernel = torch.rand(3, 5, 7, dtype=torch.float64)
    torch.testing.assert_close(direct_convolve(light, kernel), tg.bloom.fft_convolve(light, kernel))


def test_convolution_bloom_exports_to_onnx_at_two_shapes(tmp_path):
    kernel = torch.rand(3, 9, 9, generator=torch.Generator().manual_seed(2)) + 0.05
    module = tg.ConvolutionBloom(kernel, threshold=0.8, intensity=0.6)
    path = tg.onnx.export(module, tmp_path / "convolution.onnx")
    for shape in [(1, 3, 37, 53), (3, 3, 64, 96)]:
        image = hdr(shape, seed=shape[0])
        with torch.no_grad():
            peak = float(module(image).abs().max())
        assert tg.onnx.verify(module, path, image) / max(1.0, peak) <= 1e-4


def test_options_export_to_onnx_at_two_shapes(tmp_path):
    module = tg.Bloom(dirt=torch.rand(3, 6, 8, generator=torch.Generator().manual_seed(4)), **OPTIONS)
    path = tg.onnx.export(module, tmp_path / "bloom_options.onnx")
    for shape in [(1, 3, 37, 53), (3, 3, 64, 96)]:
        image = hdr(shape, seed=shape[0])
        with torch.no_grad():
            peak = float(module(image).abs().max())
        assert tg.onnx.verify(module, path, image) / max(1.0, peak) <= 1e-4


def test_convolution_stage_export_form_identity_and_checks():
    stage = tg.ConvolutionBloom(torch.rand(3, 5, 5, generator=torch.Generator().manual_seed(1)) + 0.1, threshold=0.5)
    image = hdr((1, 3, 12, 15))
    torch.testing.assert_close(stage.export_form()(image), stage(image))
    assert tg.ConvolutionBloom(torch.ones(1, 3, 3), intensity=0).is_identity and not stage.is_identity
    with pytest.raises(ValueError, match="kernel"):
        stage.kernel = torch.zeros(1, 3, 3)
