"""Tone mappers against independent float64 formulas, invariants, gradients and extremes."""

import math

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.functional import tonemap

from test_color import pixels, random_rgb, rows

LUM709 = np.array([0.2126729, 0.7151522, 0.0721750])


def ref_reinhard(rgb):
    c = np.clip(rgb, 0, 60)
    return c / (1 + c)


def ref_reinhard_extended(rgb, w=4.0):
    c = np.clip(rgb, 0, None)
    return np.clip(c * (1 + c / w**2) / (1 + c), 0, 1)


def ref_reinhard_luminance(rgb, w=4.0):
    lum = rgb @ LUM709
    out = np.empty_like(rgb)
    for i, (pixel, l_old) in enumerate(zip(rgb, lum)):
        l_new = l_old * (1 + l_old / w**2) / (1 + l_old)
        out[i] = pixel * (l_new / l_old) if l_old > 0 else pixel
    return np.clip(out, 0, 1)


def hable_t(x, a, b, c, d, e, f):
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


def ref_neutral(rgb):
    k = (0.2, 0.29, 0.24, 0.272, 0.02, 0.3)
    scale = 1 / hable_t(5.3, *k)
    return np.clip(hable_t(np.clip(rgb, 0, 60) * scale, *k) * scale, 0, 1)


def ref_hable(rgb, bias=2.0, w=11.2):
    k = (0.15, 0.50, 0.10, 0.20, 0.02, 0.30)
    return np.clip(hable_t(np.clip(rgb, 0, 60) * bias, *k) / hable_t(w, *k), 0, 1)


# --- Unity's AcesTonemap, written pixel by pixel with the shader's branches (ACES.hlsl, Color.hlsl) ---
SRGB_2_AP0 = np.array([[0.4397010, 0.3829780, 0.1773350], [0.0897923, 0.8134230, 0.0967616], [0.0175440, 0.1115440, 0.8707040]])
AP0_2_AP1 = np.array([[1.4514393161, -0.2365107469, -0.2149285693], [-0.0765537734, 1.1762296998, -0.0996759264], [0.0083161484, -0.0060324498, 0.9977163014]])
AP1_2_XYZ = np.array([[0.6624541811, 0.1340042065, 0.1561876870], [0.2722287168, 0.6740817658, 0.0536895174], [-0.0055746495, 0.0040607335, 1.0103391003]])
XYZ_2_AP1 = np.array([[1.6410233797, -0.3248032942, -0.2364246952], [-0.6636628587, 1.6153315917, 0.0167563477], [0.0117218943, -0.0082844420, 0.9883948585]])
XYZ_2_REC709 = np.array([[3.2409699419, -1.5373831776, -0.4986107603], [-0.9692436363, 1.8759675015, 0.0415550574], [0.0556300797, -0.2039769589, 1.0569715142]])
D60_2_D65 = np.array([[0.98722400, -0.00611327, 0.0159533], [-0.00759836, 1.00186000, 0.0053302], [0.00307257, -0.00509595, 1.0816800]])
AP1_Y = np.array([0.272229, 0.674082, 0.0536895])


def aces_pixel(rgb):
    aces = SRGB_2_AP0 @ np.minimum(np.maximum(rgb, 0), 60)
    ma, mi = aces.max(), aces.min()
    sat = (max(ma, 1e-4) - max(mi, 1e-4)) / max(ma, 1e-2)
    r, g, b = aces
    yc = (r + g + b + 1.75 * math.sqrt(max(b * (b - g) + g * (g - r) + r * (r - b), 0))) / 3
    x = (sat - 0.4) / 0.2
    t = max(1 - abs(x / 2), 0)
    s = (1 + math.copysign(1, x) * (1 - t * t)) / 2 if x != 0 else 0.5
    gain = 0.05 * s
    if yc <= 2 / 3 * 0.08:
        glow = gain
    elif yc >= 2 * 0.08:
        glow = 0.0
    else:
        glow = gain * (0.08 / yc - 0.5)
    aces = aces * (1 + glow)
    r, g, b = aces
    hue = 0.0 if r == g == b else math.degrees(math.atan2(math.sqrt(3) * (g - b), 2 * r - g - b))
    hue = hue + 360 if hue < 0 else hue
    centered = hue - 360 if hue > 180 else hue
    u = min(max(1 - abs(2 * centered / 135), 0), 1)
    weight = (u * u * (3 - 2 * u)) ** 2
    aces[0] += weight * sat * (0.03 - aces[0]) * (1 - 0.82)
    cg = np.maximum(AP0_2_AP1 @ aces, 0)
    cg = cg @ AP1_Y + 0.96 * (cg - cg @ AP1_Y)
    post = cg * (2.785085 * cg + 0.107772) / (cg * (2.936045 * cg + 0.887122) + 0.806889)
    xyz = AP1_2_XYZ @ post
    total = max(xyz.sum(), 1e-4)
    cx, cy = xyz[0] / total, xyz[1] / total
    big_y = min(max(xyz[1], 0), 65504) ** 0.9811
    m = big_y / max(cy, 1e-4)
    linear = XYZ_2_AP1 @ np.array([cx * m, big_y, (1 - cx - cy) * m])
    linear = linear @ AP1_Y + 0.93 * (linear - linear @ AP1_Y)
    return np.clip(XYZ_2_REC709 @ (D60_2_D65 @ (AP1_2_XYZ @ linear)), 0, 1)


def ref_aces(rgb):
    return np.array([aces_pixel(p) for p in rgb])


REFERENCES = {
    "none": lambda rgb: np.clip(rgb, 0, 1),
    "reinhard": ref_reinhard,
    "reinhard_extended": ref_reinhard_extended,
    "reinhard_luminance": ref_reinhard_luminance,
    "neutral": ref_neutral,
    "aces": ref_aces,
    "hable": ref_hable,
}


def hdr_samples():
    rgb = random_rgb(400, high=1.0, seed=3) ** 3 * 80.0  # 0..80, dense near 0
    rgb[:12] = np.array([0.0, 0.01, 0.18, 0.5, 1, 2, 4, 8, 16, 59, 60, 200])[:, None]  # greys
    rgb[12:15] = np.eye(3) * 5.0  # saturated primaries
    return rgb


def test_every_mode_has_a_reference():
    assert set(REFERENCES) == set(tg.TONEMAP_MODES)


@pytest.mark.parametrize("mode", sorted(REFERENCES))
def test_matches_independent_float64_formula(mode):
    rgb = hdr_samples()
    ours = rows(tonemap(pixels(rgb), mode))
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


def test_per_sample_white_point_equals_separate_runs():
    image = torch.rand(3, 3, 4, 5, dtype=torch.float64) * 10
    white = torch.tensor([2.0, 4.0, 8.0], dtype=torch.float64)
    batched = tg.ToneMap("reinhard_extended", white_point=white)(image)
    for i in range(3):
        torch.testing.assert_close(batched[i : i + 1], tonemap(image[i : i + 1], "reinhard_extended", white_point=white[i].item()))


def test_learnable_white_point_is_a_parameter_and_gets_a_gradient():
    layer = tg.ToneMap("reinhard_extended", white_point=torch.nn.Parameter(torch.tensor(6.0)))
    assert [name for name, _ in layer.named_parameters()] == ["white_point"]
    layer(torch.rand(1, 3, 4, 4) * 5).sum().backward()
    assert layer.white_point.grad is not None and torch.isfinite(layer.white_point.grad)


EXTREME_VALUES = [0.0, 1e-45, 1e-8, 0.18, 59.9, 60.0, 65504.0, 1e30, 3e38, -1.0, -1e30]


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_extremes_give_finite_display_values_and_gradients(mode):
    grid = [[a, b, c] for a in EXTREME_VALUES for b in (0.0, 0.18, 1e30) for c in (0.0, 65504.0)]
    image = pixels(grid, torch.float32).requires_grad_()
    out = tonemap(image, mode)
    assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    out.sum().backward()
    assert torch.isfinite(image.grad).all()


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_nan_and_inf_pixels_do_not_spread(mode):
    image = torch.rand(1, 3, 4, 4) * 4
    image[0, :, 1, 1] = torch.tensor([float("nan"), float("inf"), -float("inf")])
    clean = image.clone()
    clean[0, :, 1, 1] = 0.5
    out, expected = tonemap(image, mode), tonemap(clean, mode)
    assert torch.isfinite(out).all()
    mask = torch.ones(4, 4, dtype=torch.bool)
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
        (torch.rand(1, 4, 4, 4), ValueError),
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
