"""The HDR lattices with a tail to 65504: ``"logc_hdr"`` (LogC to 58.86 on 27 of 32 intervals, a tail on 5) and the
default, ``"logc_extended"`` (the ``"logc"`` lattice to 58.86, a tail on 12 more planes); their shape, their bakes, and
what they keep on real highlights that the ``"logc"`` lattice clamps."""

import warnings

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.lut import SHAPERS, LUT3D, LUTAccuracyWarning, bake_lut, lattice

SHAPER = SHAPERS["logc_hdr"]
EXTENDED = SHAPERS["logc_extended"]
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


def test_the_default_lattice_is_the_logc_lattice_to_58_86_and_its_knots_sit_on_planes_38_44_50_of_51():
    low, high = EXTENDED.default_domain
    for size, planes in ((51, [0, 38, 44, 50]), (101, [0, 76, 88, 100])):
        codes = EXTENDED.encode(torch.tensor([0.0, LOGC_TOP, KNEE, 65504.0], dtype=torch.float64))
        np.testing.assert_allclose(((codes - low) / (high - low)).numpy() * (size - 1), planes, rtol=0, atol=1e-9)
    x = np.concatenate(([0.0, 1e-6, 0.18, 1.0, 16.0], np.linspace(50.0, LOGC_TOP, 7)))
    np.testing.assert_allclose(EXTENDED.encode(torch.from_numpy(x)).numpy(), logc(x), rtol=0, atol=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        lut = bake_lut(tg.ToneMap("aces"))
    assert (lut.shaper, lut.size) == ("logc_extended", 51)


def test_the_clis_logc_cube_holds_the_default_lattice_plane_for_plane_up_to_58_86():
    """``torchgrade bake`` writes ``"logc"`` 39³ .cube files: the default 51³ lattice's first 39 planes on each axis."""
    look = torch.nn.Sequential(tg.ColorGrade(contrast=20.0, saturation=10.0), tg.ToneMap("aces"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        default, cube = bake_lut(look), bake_lut(look, size=39, shaper="logc")
    torch.testing.assert_close(default.table[:39, :39, :39], cube.table, atol=1e-6, rtol=0)  # the grade's float32 maths


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
    assert lut.shaper == "logc_extended"
    low, high = EXTENDED.default_domain
    inputs = EXTENDED.decode(low + lattice(9).reshape(-1, 3).t() * (high - low))
    assert float(inputs.max()) == pytest.approx(65504.0, rel=1e-9)  # no highlight is clamped
    image = inputs.reshape(1, 3, 1, -1)
    with torch.no_grad():
        torch.testing.assert_close(lut(image, "tetrahedral"), look(image), atol=1e-6, rtol=0)


def test_the_default_bake_names_no_lattice_range_while_the_logc_lattice_does():
    look = torch.nn.Sequential(tg.ColorGrade(contrast=30.0, saturation=20.0, temperature=20.0), tg.ToneMap("aces"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        default, logc = bake_lut(look), bake_lut(look, size=33, shaper="logc")
    default, logc = default.error_report.worst_case, logc.error_report.worst_case  # over the whole domain, to 65504
    assert "lattice range" not in (default.cause or "")
    assert "lattice range" in logc.cause and "58.86" in logc.cause
    assert default.p99_9 < logc.p99_9 / 2 and default.max < logc.max / 2


# ---------------------------------------------------------------- real highlights

def srgb_codes(values: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of [0, 1]-clipped values, in 8-bit codes (numpy float64, not the library's)."""
    v = np.clip(values, 0.0, 1.0)
    return 255.0 * np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


@pytest.mark.parametrize("name", ["Desk", "CandleGlass", "GoldenGate", "Carrots"])
def test_the_default_bake_misses_real_photographs_less_than_the_33_lattices_it_replaced(exr_dir, name):
    """Every 4th pixel, tetrahedral, linear entries (the bake's default), 8-bit sRGB codes against float64 direct
    evaluation of the strong ACES look: the default lattice's p99.9, max and share of values more than 1 code off are
    each at most ``"logc"``'s and ``"logc_hdr"``'s at 33³ (``"logc"`` clamps above 58.86: Desk has 1583 such pixels).
    benchmarks/results/lut_lattices.md has both looks on six photographs and sRGB entries too, where ``"logc"``'s
    p99.9 is lower on one (GoldenGate)."""
    encoding = "linear"
    from torchgrade.io import read_exr

    look = torch.nn.Sequential(tg.ColorGrade(contrast=30.0, saturation=20.0, temperature=20.0), tg.ToneMap("aces"))
    image = read_exr(exr_dir / f"{name}.exr")[:3, ::4, ::4].unsqueeze(0)
    with torch.no_grad():
        direct = srgb_codes(look(image.double()).numpy())
    figures = {}
    for shaper, size in (("auto", None), ("logc", 33), ("logc_hdr", 33)):
        lut = bake_lut(look, size=size, shaper=shaper, output_encoding=encoding, report_tolerance=float("inf"))
        with torch.no_grad():
            error = np.abs(srgb_codes(lut(image).double().numpy()) - direct)
        figures[shaper] = (float(np.quantile(error, 0.999)), float(error.max()), float((error > 1.0).mean()))
    if name == "Desk":
        assert int((image.amax(1) > LOGC_TOP).sum()) > 1000  # 1583 pixels above the "logc" lattice
    for figure in range(3):
        assert figures["auto"][figure] <= min(figures["logc"][figure], figures["logc_hdr"][figure]), (name, figures)
