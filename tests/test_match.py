"""match_look: targets made by known looks (controls recovered) and by OpenColorIO (matched with a residual LUT)."""

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.cli import main
from torchgrade.match import BoundedControls, ResidualLUT, delta_e_2000, linear_to_lab, match_errors

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

pytest.importorskip("PyOpenColorIO")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import ocio_look  # noqa: E402  (the look bench_match.py learns)


@pytest.fixture(autouse=True)
def _one_thread():
    """The fits here are a few thousand pixels, too few to share among threads: on a shared, loaded CPU a second
    thread mostly waits for the first."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def scene(exr_dir, name="GoldenGate.exr", step=16):
    """A real HDR picture, subsampled to a few thousand pixels, float64."""
    return tg.io.read_exr(exr_dir / name)[:3, ::step, ::step].double()


def test_delta_e_2000_and_lab_match_colour_science():
    rng = np.random.default_rng(1)
    rgb = rng.uniform(0.0, 1.0, (500, 3)) ** 2
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    theirs = colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, "ITU-R BT.709", apply_cctf_decoding=False), white)
    np.testing.assert_allclose(linear_to_lab(torch.from_numpy(rgb.T)).numpy().T, theirs, atol=1e-6)
    lab1 = np.stack([rng.uniform(0, 100, 2000), rng.uniform(-100, 100, 2000), rng.uniform(-100, 100, 2000)], axis=1)
    lab2 = lab1 + rng.normal(0.0, 4.0, lab1.shape)
    lab1[:20, 1:], lab2[10:30, 1:] = 0.0, 0.0  # neutral colours, where the hue is undefined
    ours = delta_e_2000(torch.from_numpy(lab1.T), torch.from_numpy(lab2.T)).numpy()
    np.testing.assert_allclose(ours, colour.delta_E(lab1, lab2, method="CIE 2000"), atol=1e-9)


def test_bounded_controls_never_leave_their_ranges():
    bounded = BoundedControls(tg.ColorGrade.controls, ("contrast", "lift", "post_exposure"))
    hable = BoundedControls(tg.ToneMap("hable").control_table(), ("white_point",))
    for raw in (-1e4, 1e4, float("nan")):
        for module in (bounded, hable):
            with torch.no_grad():
                for parameter in module.raw.values():
                    parameter.fill_(raw)
            for name, value in module.values().items():
                low, high, _ = module.ranges[name]
                if raw == raw:
                    assert torch.all((value >= low) & (value <= high)), (name, value)
    values = bounded.values()
    assert set(values) == {"contrast", "lift", "post_exposure"} and values["lift"].shape == (4,)


def test_known_look_is_matched_and_its_controls_recovered(exr_dir):
    source = scene(exr_dir)
    truth = dict(contrast=25.0, saturation=-20.0, temperature=15.0, hue_shift=10.0,
                 lift=(0.9, 1.0, 0.95, 0.03), gamma=(1.0, 1.0, 1.0, -0.1), gain=(1.0, 0.95, 0.9, 0.1),
                 split_shadows=(0.4, 0.5, 0.6), split_highlights=(0.6, 0.5, 0.4))
    target = tg.PostFX(grade=truth, tonemap="aces")(source[None])[0]
    result = tg.match_look(source, target, controls=tuple(truth), tonemaps="aces", steps=30, lbfgs_steps=300,
                           max_pixels=2048, progress=False)
    assert result.errors["controls"]["p99.9"] <= 0.5, result.errors
    fitted = result.look.to_config()["grade"]
    # Contrast, saturation and hue shift each change the picture in a way no other control can; temperature
    # is partly interchangeable with the gain's colour and split toning, so it is only recovered roughly.
    assert fitted["contrast"] == pytest.approx(25.0, abs=1.5)
    assert fitted["saturation"] == pytest.approx(-20.0, abs=1.5)
    assert fitted["hue_shift"] == pytest.approx(10.0, abs=0.5)
    assert fitted["temperature"] == pytest.approx(15.0, abs=5.0)
    assert result.history[-1] < result.history[0] / 100


def test_tone_mapper_is_chosen_and_identifiable_controls_recovered_closely(exr_dir):
    source = scene(exr_dir, "CandleGlass.exr")
    truth = dict(post_exposure=0.5, temperature=-20.0, contrast=15.0, saturation=25.0)
    target = tg.PostFX(grade=truth, tonemap="agx")(source[None])[0]
    result = tg.match_look(source, target, controls=tuple(truth), tonemaps=("neutral", "agx", "aces"), screen_steps=40,
                           steps=20, lbfgs_steps=60, max_pixels=1024, progress=False)
    assert result.look.to_config()["tonemap"] == {"mode": "agx"}
    assert min(result.candidates, key=result.candidates.get) == "agx"
    fitted = result.look.to_config()["grade"]
    for name, value in truth.items():
        assert fitted[name] == pytest.approx(value, abs=0.02 * (1.0 if name == "post_exposure" else 10.0)), (name, fitted)
    assert result.errors["controls"]["p99.9"] <= 0.1


def test_scene_referred_target_from_two_pairs_with_masks(exr_dir):
    source = scene(exr_dir)
    target = tg.ColorGrade(contrast=-20.0, saturation=30.0)(source[None])[0]
    mask = torch.rand(source.shape[1:]) < 0.5
    target[:, ~mask] = 0.0  # outside the mask the "target" is unrelated to the look
    half = source.shape[2] // 2
    sources, targets = [source[..., :half], source[..., half:]], [target[..., :half], target[..., half:]]
    result = tg.match_look(sources, targets, stages=("grade",), mask=[mask[:, :half], mask[:, half:]],
                           controls=("contrast", "saturation"), steps=20, lbfgs_steps=60, max_pixels=1024, progress=False)
    assert result.look.to_config() == {"grade": {"contrast": pytest.approx(-20.0, abs=0.01), "saturation": pytest.approx(30.0, abs=0.01)}}
    assert result.errors["controls"]["p99.9"] <= 0.1


def test_opencolorio_look_is_matched_by_controls_and_a_residual_lut(exr_dir, tmp_path):
    source = scene(exr_dir, step=8)
    target = ocio_look(source)
    result = tg.match_look(source, target, controls=("post_exposure", "color_filter", "contrast", "saturation"),
                           tonemaps="aces_reference", steps=0, lbfgs_steps=60, max_pixels=2048, residual=True,
                           residual_steps=100, progress=False)
    assert result.errors["residual"]["p99.9"] <= 1.0, result.errors
    assert result.errors["residual"]["p99.9"] < result.errors["controls"]["p99.9"]
    assert result.errors["residual"]["delta_e_2000"] < result.errors["controls"]["delta_e_2000"]
    table = result.residual.lut.table.detach()
    assert tg.match.monotonicity(table) < 1e-6
    written = result.write_cube(tmp_path / "look.cube", size=65)
    lut = tg.io.read_cube(tmp_path / "look.cube")
    with torch.no_grad():
        errors = match_errors(result.pixels.test_target.reshape(3, -1), lut(result.pixels.test_source).reshape(3, -1))
    assert written == {"size": 65, **errors}
    assert written["p99.9"] <= 1.0, written  # 65³ holds the whole look within a code


def test_residual_lut_starts_as_identity_and_bad_inputs_raise():
    display = torch.rand(1, 3, 8, 8, dtype=torch.float64)
    assert torch.allclose(ResidualLUT(9)(display), display, atol=1e-9)
    source = torch.rand(3, 8, 8)
    with pytest.raises(ValueError, match="differ in size"):
        tg.match_look(source, torch.rand(3, 8, 9), progress=False)
    with pytest.raises(ValueError, match="unknown tone mapping mode"):
        tg.match_look(source, source, tonemaps="filmic2", progress=False)
    with pytest.raises(ValueError, match="not a numeric control"):
        tg.match_look(source, source, controls=("hue_vs_hue",), tonemaps="aces", progress=False)
    with pytest.raises(ValueError, match="residual=True needs"):
        tg.match_look(source, source, stages=("grade",), residual=True, progress=False)
    with pytest.raises(ValueError, match="stages must be"):
        tg.match_look(source, source, stages=("bloom",), progress=False)


def test_cli_match_writes_a_readable_look_and_a_cube(tmp_path, capsys):
    source = tg.scene.demo_scene(24, 32)[0]
    tg.io.write_exr(tmp_path / "before.exr", source, half=False)
    target = tg.PostFX(grade={"contrast": 20, "saturation": 15}, tonemap="neutral")(source[None])[0]
    tg.cli.common.write_png(tmp_path / "after.png", target)
    status = main(["match", str(tmp_path / "before.exr"), str(tmp_path / "after.png"), "-o", str(tmp_path / "look.json"),
                   "--cube", str(tmp_path / "look.cube"), "--cube-size", "9", "--tonemap", "neutral", "--tonemap", "aces",
                   "--controls", "contrast,saturation", "--residual", "--steps", "20", "--lbfgs-steps", "30"])
    assert status == 0
    config = json.loads((tmp_path / "look.json").read_text())
    assert config["tonemap"] == {"mode": "neutral"} and config["grade"]["contrast"] == pytest.approx(20.0, abs=2.0)
    assert tg.io.read_cube(tmp_path / "look.cube").size == 9
    assert "match: neutral, 2 controls" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["missing.exr", "after.png", "-o", "look.json"], "missing.exr"),
    (["before.exr", "after.jpg", "-o", "look.json"], "must be an .exr or .png"),
    (["before.exr", "after.png", "-o", "look.txt"], "must end in .json"),
    (["before.exr", "after.png", "-o", "look.json", "--scene-referred", "--residual"], "need a display-referred target"),
])
def test_cli_match_bad_inputs_print_one_line(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    tg.io.write_exr(tmp_path / "before.exr", torch.rand(3, 4, 4), half=False)
    tg.cli.common.write_png(tmp_path / "after.png", torch.rand(3, 4, 4))
    assert main(["match", *argv]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and message in error and "Traceback" not in error
