"""Engine-parity tone mappers: ACES 1.0 against OpenColorIO, curve parameters against independent references."""

import warnings

import numpy as np
import PyOpenColorIO as OCIO
import pytest
import torch

import torchgrade as tg
from torchgrade.functional import tonemap
from torchgrade.tonemap.agx_curves import _AGX_GODOT_INSET, _AGX_GODOT_OUTSET

from reference.pixels import pixels, rows
from reference.tonemap import glsl_mat3, hdr_samples, ref_filmic, ref_unreal_filmic

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

NEW_MODES = ["filmic", "unreal_filmic", "aces_reference", "aces_hill", "aces_narkowicz", "agx", "agx_godot", "khronos_pbr_neutral"]


def ocio_aces_1_sdr_video_srgb(rgb):
    """OpenColorIO 2.6's built-in ACES 1.3 studio config: linear Rec.709 -> "sRGB - Display" / "ACES 1.0 - SDR Video"."""
    config = OCIO.Config.CreateFromBuiltinConfig("studio-config-v2.2.0_aces-v1.3_ocio-v2.4")
    processor = config.getProcessor("Linear Rec.709 (sRGB)", "sRGB - Display", "ACES 1.0 - SDR Video", OCIO.TRANSFORM_DIR_FORWARD)
    out = np.ascontiguousarray(rgb, dtype=np.float32)
    processor.getDefaultCPUProcessor().applyRGB(out)
    return np.clip(out, 0.0, 1.0)  # the ODT clips to the display range; OpenColorIO's sRGB curve does not


def hdr_colour_grid():
    """Every combination of 0 and 16 log-spaced levels 1e-4..60 per channel, plus random saturated colours."""
    levels = np.concatenate([[0.0], np.geomspace(1e-4, 60.0, 16)])
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), axis=-1).reshape(-1, 3)
    rng = np.random.default_rng(7)
    saturated = rng.uniform(0, 1, (3000, 3)) ** 4 * 10.0 ** rng.uniform(-3, 1.7, (3000, 1))
    return np.concatenate([grid, saturated])


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_aces_reference_matches_opencolorio_within_half_an_8bit_code(dtype):
    rgb = hdr_colour_grid()
    ours = rows(tg.color.linear_to_srgb(tonemap(pixels(rgb, dtype), "aces_reference")))
    codes = np.abs(ours - ocio_aces_1_sdr_video_srgb(rgb)) * 255.0
    assert codes.max() <= 0.5, f"max {codes.max():.3f} codes at {rgb[codes.max(axis=1).argmax()]}"
    assert np.percentile(codes, 99.9) <= 0.25


def test_aces_reference_greys_match_opencolorio_closely():
    grey = np.repeat(np.geomspace(1e-4, 60.0, 200)[:, None], 3, axis=1)
    ours = rows(tg.color.linear_to_srgb(tonemap(pixels(grey), "aces_reference")))
    assert np.abs(ours - ocio_aces_1_sdr_video_srgb(grey)).max() * 255.0 <= 0.05


FILMIC_CONTROLS = dict(shoulder_strength=0.22, linear_strength=0.30, linear_angle=0.10, toe_strength=0.20,
                       toe_numerator=0.01, toe_denominator=0.30, white_point=6.0, exposure_bias=1.5)


def test_filmic_parameters_match_hables_formula():
    rgb = hdr_samples()
    ours = rows(tonemap(pixels(rgb), "filmic", **FILMIC_CONTROLS))
    c = FILMIC_CONTROLS
    expected = ref_filmic(rgb, c["shoulder_strength"], c["linear_strength"], c["linear_angle"], c["toe_strength"],
                          c["toe_numerator"], c["toe_denominator"], c["white_point"], c["exposure_bias"])
    np.testing.assert_allclose(ours, expected, atol=1e-9)


def test_filmic_defaults_are_uncharted_2():
    image = pixels(hdr_samples())
    torch.testing.assert_close(tg.ToneMap("filmic")(image), tg.ToneMap("hable")(image), atol=0, rtol=0)


@pytest.mark.parametrize(
    "controls",
    [
        dict(slope=0.91, toe=0.53, shoulder=0.23, black_clip=0.0, white_clip=0.035),  # ACES-like look in Unreal's docs
        dict(slope=0.7, toe=0.85, shoulder=0.4, black_clip=0.1, white_clip=0.2),  # toe above 0.8: grey on the straight line
        dict(slope=1.0, toe=0.3, shoulder=0.8, black_clip=0.05, white_clip=0.0),  # shoulder match beyond toe match
    ],
)
def test_unreal_filmic_parameters_match_the_shader(controls):
    rgb = hdr_samples()[::4]
    ours = rows(tonemap(pixels(rgb), "unreal_filmic", **controls))
    np.testing.assert_allclose(ours, ref_unreal_filmic(rgb, **controls), atol=1e-9)


def test_unreal_filmic_keeps_middle_grey_with_default_controls():
    grey = torch.full((1, 3, 1, 1), 0.18, dtype=torch.float64)
    assert tonemap(grey, "unreal_filmic").mean().item() == pytest.approx(0.18, abs=2e-3)


def test_godot_agx_matrices_are_blenders_agx_in_rec2020():
    """Godot folds sRGB -> Rec.2020 into Blender's inset (and Rec.2020 -> sRGB into the outset); Filament publishes them unfolded."""
    inset = glsl_mat3(0.856627153315983, 0.137318972929847, 0.11189821299995, 0.0951212405381588, 0.761241990602591,
                      0.0767994186031903, 0.0482516061458583, 0.101439036467562, 0.811302368396859)
    outset = glsl_mat3(1.1271005818144368, -0.1413297634984383, -0.14132976349843826, -0.11060664309660323, 1.157823702216272,
                       -0.11060664309660294, -0.016493938717834573, -0.016493938717834257, 1.2519364065950405)
    to_2020 = colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES["sRGB"], colour.RGB_COLOURSPACES["ITU-R BT.2020"])
    np.testing.assert_allclose(np.array(_AGX_GODOT_INSET), inset @ to_2020, atol=2e-4)
    np.testing.assert_allclose(np.array(_AGX_GODOT_OUTSET), np.linalg.inv(to_2020) @ outset, atol=2e-4)


def test_agx_variants_differ_materially():
    """Godot's AgX is not a rewording of minimal AgX: saturated colours land visibly apart."""
    rgb = pixels(np.eye(3) * 4.0)
    apart = tg.color.linear_to_srgb(tonemap(rgb, "agx")) - tg.color.linear_to_srgb(tonemap(rgb, "agx_godot"))
    assert apart.abs().max() * 255 > 10


@pytest.mark.parametrize("mode", NEW_MODES)
def test_gradcheck(mode):
    image = (torch.rand(1, 3, 2, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(5)) * 3 + 0.05).requires_grad_()
    assert torch.autograd.gradcheck(lambda x: tonemap(x, mode), (image,))


@pytest.mark.parametrize("mode, controls", [("filmic", FILMIC_CONTROLS), ("unreal_filmic", dict(slope=0.88, toe=0.55, shoulder=0.26, black_clip=0.02, white_clip=0.04))])
def test_gradcheck_with_respect_to_every_control(mode, controls):
    image = torch.rand(2, 3, 2, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(6)) * 3 + 0.05
    names = list(controls)
    values = tuple(torch.tensor([controls[n], controls[n] * 0.9 + 0.01], dtype=torch.float64, requires_grad=True) for n in names)
    assert torch.autograd.gradcheck(lambda *v: tonemap(image, mode, **dict(zip(names, v))), values)


@pytest.mark.parametrize("mode, name, values", [("filmic", "shoulder_strength", [0.1, 0.3]), ("unreal_filmic", "toe", [0.3, 0.9])])
def test_per_sample_controls_equal_separate_runs(mode, name, values):
    image = torch.rand(2, 3, 4, 5, dtype=torch.float64) * 10
    batched = tg.ToneMap(mode, **{name: torch.tensor(values, dtype=torch.float64)})(image)
    for i, value in enumerate(values):
        torch.testing.assert_close(batched[i : i + 1], tonemap(image[i : i + 1], mode, **{name: value}))


def test_controls_are_stored_validated_and_learnable():
    layer = tg.ToneMap("unreal_filmic", slope=torch.nn.Parameter(torch.tensor(0.9)), white_clip=0.1)
    assert layer.to_config() == {"mode": "unreal_filmic", "slope": pytest.approx(0.9), "toe": 0.55, "shoulder": 0.26,
                              "black_clip": 0.0, "white_clip": 0.1}
    layer(torch.rand(1, 3, 4, 4) * 5).sum().backward()
    assert torch.isfinite(layer.slope.grad)
    with pytest.raises(ValueError, match="toe"):
        tg.ToneMap("unreal_filmic", toe=1.0)
    with pytest.raises(ValueError, match="toe_denominator"):
        tg.ToneMap("filmic", toe_denominator=0.0)
    with pytest.raises(ValueError, match="'agx' takes no 'slope'"):
        tg.ToneMap("agx", slope=0.9)
