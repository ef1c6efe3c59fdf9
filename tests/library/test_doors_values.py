"""Nothing silently black or NaN from finite input or a loaded file: every control and table a door lets in is checked
there (constructor, config, ``torch.load``), and what passes gives finite outputs and gradients, denormal inputs
included. Each case failed before: its docstring says how."""

import json
import re

import pytest
import torch

import torchgrade as tg
from torchgrade.lut import identity_table

DENORMALS = torch.tensor([0.0, 1e-45, 1e-40, 1e-38, 0.18, 1.0, 60.0])


def extremes_image() -> torch.Tensor:
    return DENORMALS.expand(3, -1).reshape(1, 3, 1, -1).clone()


def assert_finite_with_gradient(stage, image) -> None:
    image = image.clone().requires_grad_()
    out = stage(image)
    out.sum().backward()
    assert out.isfinite().all() and image.grad.isfinite().all()


def test_metering_mask_weights_of_any_finite_size_meter_as_their_proportions(tmp_path):
    """Weights of 1e37 summed past float32 and every output was NaN (from a config, ``grade`` wrote black, exit 0)."""
    mask = [[0.0, 1e37, 1e37], [1e37, 2e37, 1e37]]
    image = torch.rand(1, 3, 30, 40) * 4
    for metering in ("mean", "log", "histogram"):
        huge, proportions = (tg.AutoExposure(metering=metering, metering_mask=m) for m in (mask, [[0, 1, 1], [1, 2, 1]]))
        torch.testing.assert_close(huge(image), proportions(image))
    config = tmp_path / "look.json"
    config.write_text(json.dumps({"exposure": {"metering_mask": mask}, "tonemap": "aces"}))
    assert tg.PostFX.from_config(config)(image).isfinite().all()


@pytest.mark.parametrize("domain, message", [((-3e38, 3e38), "within ±1e+06"), ((0.0, 1e-45), "at least 1e-06 wide")])
def test_a_lut_domain_that_float32_cannot_span_is_refused(tmp_path, domain, message):
    """A domain of ±3e38 made an identity LUT output 0 (a black PNG, exit 0); one of [0, 1e-45] gave infinite
    gradients. Refused by the constructor, the .cube reader and a CLF Range alike."""
    with pytest.raises(ValueError, match=re.escape(message)):
        tg.LUT3D(identity_table(2), domain=domain)
    cube = tmp_path / "look.cube"
    cube.write_text(f"DOMAIN_MIN {domain[0]} {domain[0]} {domain[0]}\nDOMAIN_MAX {domain[1]} {domain[1]} {domain[1]}\n"
                    "LUT_3D_SIZE 2\n" + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 0 1\n1 0 1\n0 1 1\n1 1 1\n")
    with pytest.raises(ValueError, match="domain"):
        tg.io.read_cube(cube)
    bounds = (f"<minInValue>{domain[0]}</minInValue><maxInValue>{domain[1]}</maxInValue>"
              "<minOutValue>0</minOutValue><maxOutValue>1</maxOutValue>")
    clf = tmp_path / "look.clf"
    clf.write_text('<?xml version="1.0"?><ProcessList id="x" compCLFversion="3">'
                   f'<Range inBitDepth="32f" outBitDepth="32f">{bounds}</Range>'
                   '<LUT3D inBitDepth="32f" outBitDepth="32f"><Array dim="2 2 2 3">'
                   + " ".join(f"{r} {g} {b}" for r in (0, 1) for g in (0, 1) for b in (0, 1)) + "</Array></LUT3D></ProcessList>")
    with pytest.raises(ValueError, match=re.escape(message)):
        tg.io.read_clf(clf)


def test_a_shaper_curve_beyond_float32s_lattice_is_refused():
    """A curve of ±3e38 raised IndexError at lookup."""
    curve = torch.tensor([[0.0] * 3, [3e38] * 3])
    with pytest.raises(ValueError, match="shaper curve entries must be finite"):
        tg.LUT3D(identity_table(2), shaper="curve", curve=curve)


def test_hlg_needs_a_display_peak_where_its_gamma_is_defined_and_stays_finite_near_black():
    """At a 1-nit peak every pixel came out 1.0 (1.4 nits: 0); a pixel (0, 1e-45, 0) gave NaN, and at 1000 nits the
    gradient at 1e-45 was -inf."""
    for peak in (1.0, 1.4, 99.0):
        with pytest.raises(ValueError, match="HLG display's peak_luminance"):
            tg.Display("hlg", "rec2020", peak_luminance=peak)
        with pytest.raises(ValueError, match="HLG display's peak_luminance"):
            tg.output.encode_display(torch.rand(1, 3, 2, 2), "hlg", "rec2020", peak)
    display = tg.Display("hlg", "rec2020", peak_luminance=1000.0)
    pixels = torch.tensor([[0.0, 1e-45, 0.0], [1e-45] * 3, [0.0] * 3, [0.18] * 3, [1.0] * 3]).T.reshape(1, 3, 1, 5)
    assert_finite_with_gradient(display, pixels)
    assert display(torch.ones(1, 3, 1, 1)).flatten().tolist() == pytest.approx([1.0] * 3)


@pytest.mark.parametrize("style, controls", [
    ("linear", dict(contrast=(0.12, 0.12, 0.12))),
    ("linear", dict(contrast=(0.01, 0.5, 0.05))),
    ("log", dict(gamma=(8.0, 8.0, 8.0))),
    ("log", dict(gamma=(10.0, 9.0, 8.0))),
], ids=["linear-0.12", "linear-0.01", "log-gamma-8", "log-gamma-10"])
def test_primary_grade_powers_below_one_have_finite_gradients_at_denormals(style, controls):
    """Linear contrast at or below 0.12 and log gamma at or above 8 gave ±inf gradients at denormal inputs."""
    assert_finite_with_gradient(tg.PrimaryGrade(style, **controls), extremes_image())


def test_histogram_limits_take_per_sample_tensors():
    """``min_ev`` as a tensor raised TypeError from clamp."""
    image = torch.rand(2, 3, 20, 30) * 4
    for limits in (dict(min_ev=torch.tensor([-4.0, -3.0])), dict(min_ev=-4.0, max_ev=torch.tensor([3.0, 4.0]))):
        assert tg.AutoExposure(metering="histogram", **limits)(image).isfinite().all()


def test_a_saved_dither_draws_its_tile_again_from_its_seed(tmp_path):
    """A saved ``Dither`` whose tile was NaN loaded with ``weights_only=True`` and made every pixel NaN, in a look too."""
    dither = tg.Dither(seed=7)
    expected = dither.pattern.clone()
    dither.pattern.fill_(float("nan"))
    look = tg.PostFX(tonemap="aces", dither={"seed": 7})
    look.dither.pattern.fill_(float("nan"))
    for module, name in ((dither, "dither.pt"), (look, "look.pt")):
        torch.save(module, tmp_path / name)
    loaded = torch.load(tmp_path / "dither.pt", weights_only=True)
    assert torch.equal(loaded.pattern, expected)
    assert torch.load(tmp_path / "look.pt", weights_only=True)(torch.rand(1, 3, 8, 8)).isfinite().all()


def test_a_saved_lut_whose_size_disagrees_with_its_table_is_refused(tmp_path):
    """It loaded and looked up its table as another size (a max difference of 0.999)."""
    lut = tg.LUT3D(identity_table(5) ** 2)
    lut.size = 9
    torch.save(lut, tmp_path / "lut.pt")
    with pytest.raises(ValueError, match="size 9 holds a table of"):
        torch.load(tmp_path / "lut.pt", weights_only=True)


def test_a_saved_convolution_bloom_loads_with_weights_only(tmp_path):
    """It could not be loaded with ``weights_only=True`` at all (its class was not allowed)."""
    stage = tg.ConvolutionBloom(torch.rand(1, 5, 5) + 0.1, intensity=0.5)
    torch.save(stage, tmp_path / "bloom.pt")
    image = torch.rand(1, 3, 12, 16) * 4
    torch.testing.assert_close(torch.load(tmp_path / "bloom.pt", weights_only=True)(image), stage(image))
