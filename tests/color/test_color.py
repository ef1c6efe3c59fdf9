"""torchgrade.color against colour-science, colorsys and the published formulas, plus safety at extremes."""

import colorsys
import math
import warnings

import numpy as np
import pytest
import torch

from torchgrade import color

from reference.pixels import EXTREMES, pixels, random_rgb, rows

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour


def test_srgb_matches_colour_science_both_ways():
    values = np.linspace(0.0, 1.0, 1001)
    encoded = color.linear_to_srgb(torch.from_numpy(values))
    np.testing.assert_allclose(encoded.numpy(), colour.cctf_encoding(values, "sRGB"), atol=1e-12)
    decoded = color.srgb_to_linear(torch.from_numpy(values))
    np.testing.assert_allclose(decoded.numpy(), colour.cctf_decoding(values, "sRGB"), atol=1e-12)


def test_logc_matches_arri_ei1000_above_the_cut_and_its_formula_below():
    x = np.concatenate([np.linspace(0.0114, 58.0, 500)])
    ours = color.linear_to_logc(torch.from_numpy(x)).numpy()
    arri = colour.models.log_encoding_ARRILogC3(x, EI=1000)
    np.testing.assert_allclose(ours, arri, atol=2e-6)
    low = np.linspace(0.0, 0.0113, 50)
    formula = 0.244161 * np.log10(5.555556 * low + 0.047996) + 0.386036
    np.testing.assert_allclose(color.linear_to_logc(torch.from_numpy(low)).numpy(), formula, atol=1e-12)


def test_logc_range_tops_out_near_59():
    top = color.logc_to_linear(torch.tensor(1.0, dtype=torch.float64)).item()
    assert 58.0 < top < 59.5


@pytest.mark.parametrize(
    "function, source, target",
    [
        (color.unity_to_aces, "sRGB", "ACES2065-1"),
        (color.unity_to_acescg, "sRGB", "ACEScg"),
        (color.aces_to_acescg, "ACES2065-1", "ACEScg"),
    ],
)
def test_primaries_conversions_match_colour_science(function, source, target):
    rgb = random_rgb()
    expected = colour.RGB_to_RGB(rgb, source, target, chromatic_adaptation_transform="Bradford")
    np.testing.assert_allclose(rows(function(pixels(rgb))), expected, atol=2e-4 * 4)


@pytest.mark.parametrize(
    "forward, backward",
    [
        (color.unity_to_aces, color.aces_to_unity),
        (color.unity_to_acescg, color.acescg_to_unity),
        (color.aces_to_acescg, color.acescg_to_aces),
        (color.linear_to_srgb, color.srgb_to_linear),
        (color.linear_to_logc, color.logc_to_linear),
        (color.aces_to_acescc, color.acescc_to_aces),
    ],
)
def test_round_trips(forward, backward):
    image = pixels(random_rgb())
    torch.testing.assert_close(backward(forward(image)), image, atol=1e-10, rtol=1e-10)


def test_acescc_matches_colour_science():
    x = np.concatenate([np.linspace(2.0**-15, 1.0, 400), np.linspace(1.0, 60000.0, 100)])
    ours = color.aces_to_acescc(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(ours, colour.models.log_encoding_ACEScc(x), atol=1e-9)
    assert color.aces_to_acescc(torch.tensor(0.18, dtype=torch.float64)).item() == pytest.approx(color.ACESCC_MIDGRAY, abs=1e-7)


def test_lms_matrices_are_inverse_to_their_printed_precision():
    image = pixels(random_rgb())
    torch.testing.assert_close(color.lms_to_linear(color.linear_to_lms(image)), image, atol=2e-4, rtol=1e-4)


def test_luminance_weights_sum_to_one_so_white_has_luminance_one():
    white = torch.ones(1, 3, 2, 2, dtype=torch.float64)
    assert torch.allclose(color.luminance(white), torch.ones(1, 1, 2, 2, dtype=torch.float64), atol=1e-6)
    assert torch.allclose(color.luminance(white, "ap1"), torch.ones(1, 1, 2, 2, dtype=torch.float64), atol=1e-6)


def test_hsv_value_and_saturation_gradients_do_not_favour_a_channel_at_a_tie():
    """At grey (every channel the maximum and the minimum) and at two channels tied, the gradient of value is shared
    by the tied channels alike, so it is the same whichever channel is which (``max`` over the channels as ``amax``)."""
    for pixel in ([0.3, 0.3, 0.3], [0.8, 0.8, 0.2]):
        rgb = torch.tensor(pixel, dtype=torch.float64).reshape(1, 3, 1, 1)
        grads = []
        for order in ([0, 1, 2], [1, 0, 2], [2, 1, 0]):
            permuted = rgb[:, order].clone().requires_grad_()
            color.rgb_to_hsv(permuted)[:, 1:].sum().backward()
            grads.append(permuted.grad[:, torch.tensor(order).argsort()].flatten())
        for grad in grads[1:]:
            torch.testing.assert_close(grad, grads[0], rtol=0, atol=1e-12)


def test_hsv_matches_colorsys():
    rgb = random_rgb(high=3.0)
    rgb[:10] = rgb[:10, :1]  # grey pixels: undefined hue, zero saturation
    rgb[10] = 0.0
    rgb[11:14] = [[2.0, 2.0, 0.5], [0.3, 1.0, 1.0], [1.0, 0.2, 1.0]]  # two channels at the maximum: their formulas meet
    hsv = rows(color.rgb_to_hsv(pixels(rgb)))
    expected = np.array([colorsys.rgb_to_hsv(*p) for p in rgb])
    np.testing.assert_allclose(hsv, expected, atol=1e-12)
    back = np.array([colorsys.hsv_to_rgb(*p) for p in expected])
    np.testing.assert_allclose(rows(color.hsv_to_rgb(pixels(expected))), back, atol=1e-12)


SAFE_FUNCTIONS = [
    color.linear_to_srgb,
    color.linear_to_logc,
    lambda x: color.logc_to_linear(color.linear_to_logc(x)),
    lambda x: color.srgb_to_linear(color.linear_to_srgb(x)),
    lambda x: color.acescc_to_aces(color.aces_to_acescc(color.unity_to_aces(x))),
    color.unity_to_acescg,
    color.linear_to_lms,
    color.rgb_to_hsv,
    lambda x: color.hsv_to_rgb(color.rgb_to_hsv(x)),
    color.luminance,
]


@pytest.mark.parametrize("function", SAFE_FUNCTIONS)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_outputs_and_gradients_are_finite_at_extremes(function, dtype):
    grey = [[v, v, v] for v in EXTREMES]
    mixed = [[v, 0.5 * v, 0.0] for v in EXTREMES]
    image = pixels(grey + mixed, dtype).requires_grad_(True)
    out = function(image)
    assert torch.isfinite(out).all()
    out.sum().backward()
    assert torch.isfinite(image.grad).all()


@pytest.mark.parametrize(
    "function",
    [color.linear_to_srgb, color.srgb_to_linear, color.linear_to_logc, color.rgb_to_hsv, color.hsv_to_rgb, color.aces_to_acescc],
)
def test_gradcheck(function):
    image = torch.rand(1, 3, 3, 4, dtype=torch.float64) * 0.9 + 0.05
    assert torch.autograd.gradcheck(function, (image.requires_grad_(),))


def test_srgb_curve_constants_are_iec_61966():
    assert color.linear_to_srgb(torch.tensor(1.0, dtype=torch.float64)).item() == pytest.approx(1.0, abs=1e-12)
    x = torch.tensor(0.5, dtype=torch.float64)
    assert color.linear_to_srgb(x).item() == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055, abs=1e-15)
    assert color.srgb_to_linear(torch.tensor(0.04, dtype=torch.float64)).item() == pytest.approx(0.04 / 12.92)
    assert math.isfinite(color.linear_to_srgb(torch.tensor(0.0)).item())
