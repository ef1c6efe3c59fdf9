"""The report a colourist can plan on: beside the realistic colours, its figures on colour charts and warm practicals
(:mod:`torchgrade.lut.footage`), each within 2x of what the LUT really gets on pictures of that footage, every pixel
counted. The pictures are built from colour-science's reference data, which the library never reads
(``benchmarks/lut_footage.py``): the ColorChecker SG (140 patches) and ColorChecker 2005 charts at exposures between the
report's, and candle-lit still lifes of spectral test samples (NIST CQS 9.0, CIE 13.3) lit by black bodies at
1850-2650 K; and the sample photographs. Also: ``frames=`` measures every pixel, and the default report's cost in
colours evaluated."""

import sys
import warnings
from pathlib import Path

import colour
import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchgrade as tg  # noqa: E402
from benchmarks.lut_footage import CHARTS, LOOKS, OBSERVER, PHOTOGRAPHS, REC709, SPECTRUM, STILL_LIFE_KELVIN  # noqa: E402
from benchmarks.lut_footage import chart_picture, still_life  # noqa: E402
from torchgrade.lut import LUTAccuracyWarning, bake_lut  # noqa: E402
from torchgrade.lut.footage import chart_colours, colorchecker_rec709, planckian_rec709, warm_colours  # noqa: E402

TESTED_LOOKS = ("cinematic (export/looks/cinematic.json)", "README Python: contrast 20, saturation 10, ACES")
"""The shipped look and the README's, their per-pixel stages baked as ``bake_lut`` bakes them by default (51³);
``benchmarks/results/lut_footage.md`` has three more."""

MARGIN = 2.0
"""The report's figure for a footage is within this factor, either way, of the p99.9 the LUT gets on a picture of it."""


def srgb_codes(values: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of [0, 1]-clipped values, in 8-bit codes (numpy float64, not the library's)."""
    v = np.clip(values, 0.0, 1.0)
    return 255.0 * np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def p99_9(errors: np.ndarray) -> float:
    return float(np.quantile(errors, 0.999, method="higher"))


def real_errors(lut, transform, pixels: torch.Tensor) -> np.ndarray:
    """8-bit sRGB code errors of ``lut`` against ``transform`` in float64 on every channel value of ``pixels``."""
    with torch.no_grad():
        direct = transform(pixels.double()).numpy()
        looked_up = lut(pixels.float()).double().numpy()
    return np.abs(srgb_codes(looked_up) - srgb_codes(direct))


@pytest.fixture(scope="module", params=TESTED_LOOKS)
def baked(request):
    look = tg.PostFX.from_config(LOOKS[request.param]).eval()
    transform = look.per_pixel_stages()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        lut = bake_lut(transform)
    return look, transform, lut, {kind.colour_set: kind for kind in lut.error_report.footage}


# ---------------------------------------------------------------- the sets, against colour-science


def test_the_chart_colours_are_colour_sciences_colorchecker_in_rec709():
    chart = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    expected = colour.XYZ_to_RGB(colour.xyY_to_XYZ(np.array(list(chart.data.values()))), REC709,
                                 illuminant=chart.illuminant, chromatic_adaptation_transform="Bradford")
    np.testing.assert_allclose(colorchecker_rec709().numpy().T, expected, rtol=0, atol=2e-4)  # its D50 has more digits


@pytest.mark.parametrize("kelvin", [1667.0, 1800.0, 2222.0, 2700.0, 4000.0])
def test_the_planckian_lights_are_colour_sciences_black_body_within_0_001_in_xy(kelvin):
    rgb = planckian_rec709(torch.tensor([kelvin])).numpy()[:, 0]
    xy = colour.XYZ_to_xy(colour.RGB_to_XYZ(rgb, REC709, illuminant=REC709.whitepoint, chromatic_adaptation_transform=None))
    black_body = colour.XYZ_to_xy(colour.sd_to_XYZ(colour.sd_blackbody(kelvin, SPECTRUM), OBSERVER, method="Integration"))
    np.testing.assert_allclose(xy, black_body, rtol=0, atol=1e-3)
    assert rgb @ np.array([0.2126729, 0.7151522, 0.0721750]) == pytest.approx(1.0, abs=1e-4)  # Y = 1


def test_the_footage_figures_are_the_error_on_their_colours_and_the_report_names_them():
    transform = torch.nn.Sequential(tg.ColorGrade(contrast=30.0, saturation=20.0), tg.ToneMap("aces"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        lut = bake_lut(transform, size=17, report_tolerance=float("inf"))
    report = lut.error_report
    assert [kind.colour_set for kind in report.footage] == ["colour charts", "warm practicals"]
    for kind, colours in zip(report.footage, (chart_colours(), warm_colours())):
        errors = real_errors(lut, transform, colours.reshape(1, 3, 1, -1))
        assert kind.colours == colours.shape[1] and not kind.binding
        assert kind.p99_9 == pytest.approx(p99_9(errors), abs=1e-6) and kind.max == pytest.approx(errors.max(), abs=1e-6)
        assert f"on {kind.colour_set}: p99.9 {kind.p99_9:.2f}" in str(report)


# ---------------------------------------------------------------- within 2x of the truth, every pixel


PICTURES = [("colour charts", chart_picture, name) for name in CHARTS] + [
    ("warm practicals", still_life, kelvin) for kelvin in STILL_LIFE_KELVIN]
"""Each footage figure and the pictures of that footage: the charts, the candle-lit still lifes."""


@pytest.mark.parametrize("figure, build, argument", PICTURES, ids=[f"{figure}: {argument}" for figure, _, argument in PICTURES])
def test_each_footage_figure_is_within_twice_the_error_on_a_picture_of_that_footage(baked, figure, build, argument):
    _, transform, lut, footage = baked
    real = p99_9(real_errors(lut, transform, build(argument)))
    stated = footage[figure].p99_9
    assert real / MARGIN <= stated <= real * MARGIN, (stated, real)


@pytest.mark.parametrize("image", PHOTOGRAPHS)
def test_the_realistic_figure_is_within_twice_the_error_on_each_natural_photograph(baked, exr_dir, image):
    from torchgrade.io import read_exr

    look, transform, lut, _ = baked
    with torch.no_grad():
        received = look.per_pixel_input(read_exr(exr_dir / f"{image}.exr")[:3].unsqueeze(0))
    real = p99_9(real_errors(lut, transform, received))
    stated = lut.error_report.p99_9
    assert real / MARGIN <= stated <= real * MARGIN, (stated, real)


def test_a_report_on_frames_takes_its_maximum_over_every_pixel():
    """400 × 400 pixels, more than the diagnosis's 65,536: black (on a lattice plane: no error) but one bright saturated
    pixel off the diagnosis's stride, and the report's max is its error."""
    transform = torch.nn.Sequential(tg.ColorGrade(contrast=30.0, saturation=20.0), tg.ToneMap("aces"))
    frames = torch.zeros(1, 3, 400, 400)
    frames[0, :, 201, 133] = torch.tensor([4.0, 0.5, 0.02])  # flat index 80533: odd, off every second pixel
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        lut = bake_lut(transform, size=9, frames=frames)
    errors = real_errors(lut, transform, frames)
    report = lut.error_report
    assert report.colours == 160000 and errors.max() > 1.0 and errors[..., 200, 133].max() < 1e-6
    assert report.max == pytest.approx(errors.max(), abs=1e-5) and report.p99_9 == pytest.approx(p99_9(errors), abs=1e-5)


def test_the_default_report_evaluates_the_colours_it_states():
    """Every colour the transform sees in a default bake of an HDR transform whose highlights hold (so no finer lattice
    is baked) and within tolerance (no diagnosis): the 51³ lattice, 16,384 realistic, 24 patches at 257 exposures,
    8,192 warm, 16,384 footage-like and 9³ gamut-grid validation colours, 6 · 64 · 8² bright saturated colours."""
    class Counting(torch.nn.Module):
        expects_hdr, pixels = True, 0

        def forward(self, image):
            self.pixels += image[..., 0, :, :].numel()
            return image / (1.0 + image.clamp_min(0.0))

    counting = Counting()
    report = bake_lut(counting, report_tolerance=float("inf")).error_report
    assert report.highlights is not None and report.highlights.max <= 2.0
    assert counting.pixels == 51 ** 3 + 16384 + 24 * 257 + 8192 + 16384 + 9 ** 3 + 6 * 64 * 8 ** 2
