"""The default HDR lattice (``"logc_hdr"``): LogC to 58.86, then a tail to 65504 on the last lattice planes; its
shape, its bake, and what it keeps on real highlights that the ``"logc"`` lattice clamps."""

import warnings

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.lut import SHAPERS, LUT3D, LUTAccuracyWarning, bake_lut, lattice

SHAPER = SHAPERS["logc_hdr"]
A, B, C, D = 5.555556, 0.047996, 0.244161, 0.386036  # Unity's LinearToLogC constants (ColorGrading.hlsl)
LOGC_TOP = (10.0 ** ((1.0 - D) / C) - B) / A  # linear value of LogC code 1
KNEE = (10.0 ** ((1.3 - D) / C) - B) / A  # linear value of LogC code 1.3 (≈ 997)


def logc(x: np.ndarray) -> np.ndarray:
    return C * np.log10(A * x + B) + D


def lattice_coordinate(x, size: int = 33) -> np.ndarray:
    """Where linear values land on a ``size``-point axis of the default domain."""
    low, high = SHAPER.default_domain
    codes = SHAPER.encode(torch.as_tensor(np.asarray(x, dtype=np.float64)))
    return ((codes - low) / (high - low)).numpy() * (size - 1)


def test_below_58_86_the_shaper_is_logc():
    x = np.concatenate(([0.0, 1e-6, 0.18, 1.0, 16.0], np.linspace(50.0, LOGC_TOP, 7)))
    np.testing.assert_allclose(SHAPER.encode(torch.from_numpy(x)).numpy(), logc(x), rtol=0, atol=1e-12)


def test_the_knots_sit_on_lattice_planes_27_31_32_of_a_33_lattice_and_on_planes_of_finer_ones():
    """Black to 58.86 keeps 27 of 32 intervals, 58.86 to LogC 1.3 gets 4, the rest up to 65504 gets 1."""
    for size, planes in ((33, [0, 27, 31, 32]), (65, [0, 54, 62, 64]), (129, [0, 108, 124, 128]), (17, [0, 13.5, 15.5, 16])):
        np.testing.assert_allclose(lattice_coordinate([0.0, LOGC_TOP, KNEE, 65504.0], size), planes, rtol=0, atol=1e-9)


def test_the_tail_spaces_the_lattice_evenly_in_stops():
    """Above 58.86 each segment is linear in log2(x) to within 2e-4 stops (LogC's ``b`` is negligible there)."""
    for low, high in ((LOGC_TOP, KNEE), (KNEE, 65504.0)):
        x = np.geomspace(low, high, 9)
        steps = np.diff(lattice_coordinate(x))
        np.testing.assert_allclose(steps, steps.mean(), rtol=2e-3)
    per_stop = [np.diff(lattice_coordinate([lo, 2 * lo]))[0] for lo in (LOGC_TOP, KNEE)]
    np.testing.assert_allclose(per_stop, [4 / np.log2(KNEE / LOGC_TOP), 1 / np.log2(65504.0 / KNEE)], rtol=2e-3)


def test_it_is_continuous_monotone_and_exactly_invertible_up_to_65504():
    x = torch.cat((torch.zeros(1), torch.logspace(-8, np.log10(65504.0), 20001, dtype=torch.float64)))
    codes = SHAPER.encode(x)
    assert bool((codes[1:] > codes[:-1]).all())
    torch.testing.assert_close(SHAPER.decode(codes), x, rtol=1e-9, atol=1e-12)
    for knot in (LOGC_TOP, KNEE):
        around = SHAPER.encode(torch.tensor([knot * (1 - 1e-12), knot, knot * (1 + 1e-12)], dtype=torch.float64))
        assert float(around.max() - around.min()) < 1e-11


def test_gradients_stay_finite_at_the_extremes():
    image = torch.tensor([0.0, 1e-38, 0.18, LOGC_TOP, KNEE, 65504.0, 1e30, -5.0]).repeat(3, 1).reshape(1, 3, 1, 8)
    image.requires_grad_(True)
    table = lattice(5, torch.float32).requires_grad_(True)
    LUT3D(table, "logc_hdr")(image).sum().backward()
    assert bool(torch.isfinite(image.grad).all()) and bool(torch.isfinite(table.grad).all())


def test_the_bake_reproduces_the_transform_on_its_lattice_up_to_65504():
    look = torch.nn.Sequential(tg.ColorGrade(contrast=20.0, saturation=10.0), tg.ToneMap("aces"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        lut = bake_lut(look, size=9)
    assert lut.shaper == "logc_hdr"
    low, high = SHAPER.default_domain
    inputs = SHAPER.decode(low + lattice(9).reshape(-1, 3).t() * (high - low))
    assert float(inputs.max()) == pytest.approx(65504.0, rel=1e-9)  # no highlight is clamped
    image = inputs.reshape(1, 3, 1, -1)
    with torch.no_grad():
        torch.testing.assert_close(lut(image, "tetrahedral"), look(image), atol=1e-6, rtol=0)


def test_the_default_bake_names_no_lattice_range_while_the_logc_lattice_does():
    look = torch.nn.Sequential(tg.ColorGrade(contrast=30.0, saturation=20.0, temperature=20.0), tg.ToneMap("aces"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        default, logc = bake_lut(look, size=33), bake_lut(look, size=33, shaper="logc")
    default, logc = default.error_report.worst_case, logc.error_report.worst_case  # over the whole domain, to 65504
    assert "lattice range" not in (default.cause or "")
    assert "lattice range" in logc.cause and "58.86" in logc.cause
    assert default.p99_9 < logc.p99_9 / 2 and default.max < logc.max / 2


# ---------------------------------------------------------------- real highlights

HIGHLIGHT_MAX = 5.0
"""Codes a default 33³ bake of the strong look may miss by on pixels with a channel above 58.86 (tetrahedral; measured
4.4 / 0 / 1.1 on Desk / CandleGlass / GoldenGate with sRGB entries, 4.5 / 0 / 1.1 with linear ones; the ``"logc"``
lattice: 17.5 / 2.9 / 0, benchmarks/results/lut.md)."""

MIDTONE_P999 = {"srgb": {"Desk": 6.5, "CandleGlass": 1.0, "GoldenGate": 2.0},
                "linear": {"Desk": 7.8, "CandleGlass": 2.1, "GoldenGate": 3.2}}
"""The p99.9 the tail costs (measured 5.87 / 0.85 / 1.60 sRGB, 7.10 / 1.82 / 2.84 linear; on the ``"logc"`` lattice
4.66 / 0.65 / 1.14 and 5.52 / 1.33 / 2.07), with a margin."""


def srgb_codes(values: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of [0, 1]-clipped values, in 8-bit codes (numpy float64, not the library's)."""
    v = np.clip(values, 0.0, 1.0)
    return 255.0 * np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


@pytest.mark.parametrize("name", ["Desk", "CandleGlass", "GoldenGate"])
@pytest.mark.parametrize("encoding", ["srgb", "linear"])
def test_default_33_bake_keeps_real_highlights_within_a_few_codes(exr_dir, name, encoding):
    """Every 4th pixel, tetrahedral, 8-bit sRGB codes against float64 direct evaluation of the strong ACES look."""
    from torchgrade.io import read_exr

    look = torch.nn.Sequential(tg.ColorGrade(contrast=30.0, saturation=20.0, temperature=20.0), tg.ToneMap("aces"))
    image = read_exr(exr_dir / f"{name}.exr")[:3, ::4, ::4].unsqueeze(0)
    lut = bake_lut(look, size=33, output_encoding=encoding, report_tolerance=float("inf"))
    with torch.no_grad():
        error = np.abs(srgb_codes(lut(image).double().numpy()) - srgb_codes(look(image.double()).numpy()))
    above = np.broadcast_to((image.amax(1, keepdim=True) > LOGC_TOP).numpy(), error.shape)
    if name == "Desk":
        assert above.any(axis=1).sum() > 1000  # 1583 such pixels
    assert error[above].max(initial=0.0) <= HIGHLIGHT_MAX, (name, float(error[above].max(initial=0.0)))
    assert np.quantile(error, 0.999) <= MIDTONE_P999[encoding][name], (name, float(np.quantile(error, 0.999)))
