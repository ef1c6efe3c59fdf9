"""The torchgrade command: demo, grade and bake, as a user runs them."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

import torchgrade as tg
from torchgrade.cli import main


def test_demo_writes_a_graded_png_and_prints_one_line(tmp_path, capsys):
    out = tmp_path / "demo.png"
    assert main(["demo", "--output", str(out), "--width", "160", "--height", "90", "--exr", str(tmp_path / "scene.exr")]) == 0
    line = capsys.readouterr().out.strip()
    assert "\n" not in line and "160x90" in line and "ToneMap" in line and " ms" in line
    pixels = np.asarray(Image.open(out))
    assert pixels.shape == (90, 160, 3)
    assert 10 < pixels.mean() < 200 and pixels.std() > 20  # a lit scene, neither black nor blown out
    scene = tg.io.read_exr(tmp_path / "scene.exr")
    assert scene.shape == (3, 90, 160) and scene.max() >= 200  # the lamp and glints stay HDR in the EXR


def test_demo_scene_has_the_promised_content():
    scene = tg.scene.demo_scene(180, 320)
    assert scene.shape == (1, 3, 180, 320)
    assert (scene == 1000).all(dim=1).sum() >= 3  # single-pixel glints
    assert (scene.amax(dim=1) == 200).any()  # the lamp of 200
    assert ((scene.amax(dim=1) > 5) & (scene.amax(dim=1) <= 8.5)).sum() > 50  # emissive objects around 8
    assert scene.min() >= 0 and scene.median() < 0.5  # a dim room


def test_grade_command_grades_an_exr(exr_dir, tmp_path):
    out = tmp_path / "desk.png"
    result = subprocess.run(
        [sys.executable, "-m", "torchgrade.cli", "grade", str(exr_dir / "Desk.exr"), "-o", str(out), "--tonemap", "neutral", "--contrast", "20"],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert np.asarray(Image.open(out)).shape == (874, 644, 3)


def test_grade_command_reports_bad_arguments_without_a_traceback(exr_dir, tmp_path, capsys):
    assert main(["grade", str(exr_dir / "Desk.exr"), "-o", str(tmp_path / "x.jpg")]) == 2
    assert main(["grade", str(exr_dir / "Desk.exr"), "-o", str(tmp_path / "x.png"), "--contrast", "500"]) == 2
    err = capsys.readouterr().err
    assert "must end in .png or .exr" in err and "contrast must lie in" in err
    assert not list(tmp_path.iterdir())


def graded_scene(tmp_path, *arguments) -> torch.Tensor:
    """What ``torchgrade grade`` hands the look: an identity grade's frame, written before tone mapping in float."""
    out = tmp_path / "frame.exr"
    assert main(["grade", *map(str, arguments), "-o", str(out), "--tonemap", "none", "--scene-referred", "--bit-depth", "float", "-q"]) == 0
    return tg.io.read_exr(out)


def test_grade_converts_an_ap0_file_to_rec709_as_opencolorio_does(exr_dir, tmp_path):
    import PyOpenColorIO as ocio

    stored = tg.io.read_exr(exr_dir / "Carrots.exr")[:3]  # ACES AP0 chromaticities
    pixels = np.ascontiguousarray(stored.permute(1, 2, 0).numpy())
    config = ocio.Config.CreateFromBuiltinConfig("cg-config-latest")
    config.getProcessor("ACES2065-1", "Linear Rec.709 (sRGB)").getDefaultCPUProcessor().applyRGB(pixels)
    expected = torch.from_numpy(pixels).permute(2, 0, 1)
    torch.testing.assert_close(graded_scene(tmp_path, exr_dir / "Carrots.exr"), expected, atol=1e-5, rtol=1e-4)
    assert (stored - expected).abs().max() > 0.05  # the conversion is not a no-op on this file
    torch.testing.assert_close(graded_scene(tmp_path, exr_dir / "Carrots.exr", "--no-to-rec709"), stored, atol=0, rtol=0)


@pytest.mark.parametrize("adaptation, low, high", [(None, 0.0, 1.4), ("none", 0.0, 1.4), ("bradford", 30.0, 60.0)])
def test_grade_converts_an_xyz_file_to_its_rec709_twin(exr_dir, tmp_path, adaptation, low, high):
    # OpenEXR's README: the Chromaticities images look the same. They do when XYZ is taken as it is
    # (the default "auto" for XYZ primaries); a Bradford adaptation from XYZ's E white is 54 codes off.
    flags = [] if adaptation is None else ["--adaptation", adaptation]
    codes = lambda linear: tg.color.linear_to_srgb(linear.clamp(0, 1)) * 255  # noqa: E731
    graded = graded_scene(tmp_path, exr_dir / "formats" / "XYZ.exr", *flags)
    error = (codes(graded) - codes(tg.io.read_exr(exr_dir / "formats" / "Rec709.exr"))).abs().max()
    assert low <= error <= high, error


def test_grade_help_names_the_chromaticities_default(capsys):
    with pytest.raises(SystemExit):
        main(["grade", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--to-rec709, --no-to-rec709" in text and "Rec.709, the primaries the look works in (default)" in text


def test_bake_writes_the_cube_of_the_graded_look(tmp_path, capsys):
    out = tmp_path / "look.cube"
    assert main(["bake", "-o", str(out), "--size", "17", "--contrast", "20", "--saturation", "10", "--tonemap", "neutral",
                 "--accept-error"]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("bake: 17³ logc LUT of ColorGrade -> ToneMap") and str(out) in line
    look = torch.nn.Sequential(tg.ColorGrade(contrast=20, saturation=10), tg.ToneMap("neutral"))
    expected = tg.bake_lut(look, size=17, shaper="logc")  # auto bakes logc for a .cube: its 1D section stops at 58.86
    written = tg.io.read_cube(out)
    assert written.size == 17 and written.shaper == "curve"  # the LogC shaper travels as a 1D section
    image = tg.scene.demo_scene(45, 80)
    with torch.no_grad():
        torch.testing.assert_close(written(image).clamp(0, 1), expected(image).float(), atol=2e-3, rtol=0)  # the display's clip


def test_bake_with_fitted_entries_writes_another_table_and_reports_its_smaller_error(tmp_path, capsys):
    flags = ["--size", "9", "--contrast", "30", "--saturation", "20", "--tonemap", "aces", "--accept-error"]
    reports = {}
    for entries in ("sampled", "fitted"):
        assert main(["bake", "-o", str(tmp_path / f"{entries}.cube"), "--entries", entries, *flags]) == 0
        reports[entries] = capsys.readouterr().out
    tables = [tg.io.read_cube(tmp_path / f"{entries}.cube").table for entries in reports]
    assert (tables[0] - tables[1]).abs().max() > 1e-3
    p999 = {entries: float(text.split("p99.9 ")[1].split(",")[0]) for entries, text in reports.items()}
    assert p999["fitted"] < 0.8 * p999["sampled"], reports


def test_bake_from_a_config_covers_the_scene_as_the_lut_receives_it(exr_dir, tmp_path, capsys):
    """With exposure and bloom left live, the lattice covers the scene after them, and the error is measured there."""
    out = tmp_path / "cinematic.cube"
    config = Path(__file__).resolve().parents[2] / "export" / "looks" / "cinematic.json"
    scene_path = exr_dir / "CandleGlass.exr"
    assert main(["bake", "--config", str(config), "-o", str(out), "--size", "9", "--scene", str(scene_path), "--accept-error"]) == 0
    line = capsys.readouterr().out.strip()
    assert "left live, not in the LUT: exposure, bloom" in line and "on CandleGlass.exr:" in line
    look = tg.PostFX.from_config(config)
    with torch.no_grad():
        received = look.per_pixel_input(tg.io.read_exr(scene_path)[:3].unsqueeze(0))
    assert float(out.read_text().splitlines()[2].split()[-1]) == pytest.approx(float(received.max()), rel=1e-4)  # LUT_1D_INPUT_RANGE


@pytest.mark.parametrize("arguments, message", [
    (["--size", "300"], "LUT size must be an integer from 2 to 256"),
    (["--size", "auto"], "--size auto needs --scene"),
    (["--tolerance", "1"], "--tolerance goes with --size auto"),
    (["--config", "missing.json"], "missing.json"),
    (["--config", "look.json", "--contrast", "20"], "give --config or grading flags, not both"),
])
def test_bake_reports_bad_arguments_without_writing(tmp_path, capsys, arguments, message):
    assert main(["bake", "-o", str(tmp_path / "x.cube"), *arguments]) == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("output, message", [("x.png", "must end in .cube"), ("missing/x.cube", "does not exist"), ("folder.cube", "folder.cube")])
def test_bake_refuses_a_bad_output_before_baking(tmp_path, capsys, output, message):
    (tmp_path / "folder.cube").mkdir()
    assert main(["bake", "-o", str(tmp_path / output), "--size", "5"]) == 2
    assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.cube"]


def test_export_writes_a_verified_onnx_file_and_reports_it(tmp_path, capsys):
    config = tmp_path / "look.json"
    config.write_text('{"exposure": {"speed": 1.5}, "grade": {"contrast": 15}, "tonemap": "neutral"}')
    out = tmp_path / "look.onnx"
    assert main(["export", "--config", str(config), "--out", str(out), "--width", "48", "--height", "32"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert out.exists() and len(lines) == 3
    assert "exposure -> grade -> tonemap" in lines[0] and int(lines[0].split()[-2]) == tg.onnx.node_count(out)
    assert "(32, 48)" in lines[1] and float(lines[1].split()[-1]) < 1e-4
    assert lines[2].endswith("ms (median of 5)")


@pytest.mark.parametrize("whole_frame", [False, True])
def test_export_runs_the_per_pixel_stages_in_strips_unless_asked_for_the_whole_frame(tmp_path, capsys, whole_frame):
    import onnx

    config = tmp_path / "look.json"
    config.write_text('{"grade": {"contrast": 15}, "tonemap": "aces"}')
    out = tmp_path / "look.onnx"
    flags = ["--whole-frame"] if whole_frame else []
    assert main(["export", "--config", str(config), "--out", str(out), "--width", "40", "--height", "24", *flags]) == 0
    errors = dict(part.rsplit(" ", 1) for part in capsys.readouterr().out.splitlines()[1].split("PyTorch: ")[1].split(", "))
    assert float(errors["onnxruntime"]) < 1e-4 and float(errors["openvino f32"]) < 1e-4
    assert any(node.op_type == "Scan" for node in onnx.load(str(out)).graph.node) != whole_frame


def test_export_of_a_baked_look_reports_the_lut_error_and_both_runtimes(tmp_path, capsys):
    config = tmp_path / "look.json"
    config.write_text('{"grade": {"contrast": 15, "saturation": 10}, "tonemap": "neutral"}')
    out = tmp_path / "look.onnx"
    assert main(["export", "--config", str(config), "--out", str(out), "--lut", "9", "--output", "srgb8",
                 "--width", "24", "--height", "16", "--accept-error"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    look = tg.PostFX.from_config(str(config)).to_lut(9)
    assert lines[0].endswith(f"{tg.onnx.node_count(out)} nodes") and "output srgb8" in lines[0]
    assert lines[1] == f"  baked LUT vs the look it replaces: {look.lut.error_report}"
    errors = dict(part.rsplit(" ", 1) for part in lines[2].split("PyTorch: ")[1].split(", "))
    assert sorted(errors) == ["onnxruntime", "openvino default", "openvino f32"]
    assert float(errors["onnxruntime"]) <= 1 and float(errors["openvino f32"]) <= 1  # 8-bit codes
    assert "onnxruntime" in lines[3] and "openvino f32" in lines[3]


def test_export_of_a_lut_over_its_tolerance_exits_3_writes_nothing_and_says_what_to_do(tmp_path, capsys):
    config = tmp_path / "look.json"
    config.write_text('{"grade": {"contrast": 15, "saturation": 10}, "tonemap": "neutral"}')
    out = tmp_path / "look.onnx"
    assert main(["export", "--config", str(config), "--out", str(out), "--lut", "9", "--width", "24", "--height", "16"]) == 3
    err = capsys.readouterr().err
    assert "torchgrade export: error: the baked LUT misses the look" in err and "realistic colours" in err
    assert "--lut above 9" in err and "no --lut" in err and "--accept-error" in err
    assert not out.exists()


def test_export_verifies_on_the_given_exrs(exr_dir, tmp_path, capsys):
    config = tmp_path / "look.json"
    config.write_text('{"grade": {"contrast": 15}, "tonemap": "aces"}')
    out = tmp_path / "look.onnx"
    assert main(["export", "--config", str(config), "--out", str(out), "--scene", str(exr_dir / "GrayRampsHorizontal.exr")]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].endswith(f"{tg.onnx.node_count(out)} nodes")
    errors = dict(part.rsplit(" ", 1) for part in lines[1].split("PyTorch: ")[1].split(", "))
    assert float(errors["onnxruntime"]) < 1e-4 and float(errors["openvino f32"]) < 1e-4
    assert lines[2].startswith("  latency on GrayRampsHorizontal.exr") and lines[2].endswith("ms (median of 5)")


def test_export_reports_a_bad_output_without_a_traceback(tmp_path, capsys):
    config = tmp_path / "look.json"
    config.write_text('{"tonemap": "neutral"}')
    assert main(["export", "--config", str(config), "--out", str(tmp_path / "look.txt")]) == 2
    assert "export: error: output must be a .onnx file" in capsys.readouterr().err


# --- nothing a user owns is lost ------------------------------------------------------------------


def _plate(folder: Path, name: str = "plate.0001.exr") -> Path:
    folder.mkdir(exist_ok=True)
    path = folder / name
    tg.io.write_exr(path, torch.full((3, 4, 6), 10.0))
    return path


@pytest.mark.parametrize("link", ["same path", "another spelling", "symbolic link", "hard link"])
def test_grade_never_writes_over_its_input(tmp_path, capsys, link):
    plate = _plate(tmp_path / "ow")
    before = plate.read_bytes()
    output = {"same path": plate, "another spelling": tmp_path / "ow" / ".." / "ow" / plate.name}.get(link)
    if link == "symbolic link":
        output = tmp_path / "link.exr"
        output.symlink_to(plate)
    elif link == "hard link":
        output = tmp_path / "hard.exr"
        output.hardlink_to(plate)
    assert main(["grade", str(plate), "-o", str(output), "--contrast", "20"]) == 2
    assert "would replace the input" in capsys.readouterr().err
    assert plate.read_bytes() == before


def test_grading_a_shot_over_its_own_frames_writes_none_of_them(tmp_path, capsys):
    frames = [_plate(tmp_path / "ow", f"plate.{n:04d}.exr") for n in (1, 2, 3)]
    before = [frame.read_bytes() for frame in frames]
    assert main(["grade", str(tmp_path / "ow"), "-o", str(tmp_path / "ow" / "plate.%04d.exr"), "-q"]) == 2
    assert "would replace the input" in capsys.readouterr().err
    assert [frame.read_bytes() for frame in frames] == before


def test_overwrite_input_grades_in_place_when_asked(tmp_path, capsys):
    plate = _plate(tmp_path / "ow")
    assert main(["grade", str(plate), "-o", str(plate), "--scene-referred", "--contrast", "20", "--overwrite-input"]) == 0
    assert tg.io.read_exr(plate).max() != 10.0  # graded: contrast moved the value


def test_two_outputs_of_one_command_cannot_be_one_file(tmp_path, capsys):
    png = tmp_path / "demo.png"
    (tmp_path / "demo.exr").symlink_to(png)
    assert main(["demo", "-o", str(png), "--exr", str(tmp_path / "demo.exr"), "--width", "16", "--height", "9"]) == 2
    assert "are the same file" in capsys.readouterr().err


@pytest.mark.parametrize("output", ["out.exr", "out.png"])
def test_a_look_that_changes_nothing_writes_the_non_finite_policys_values(exr_dir, tmp_path, output):
    """An empty look builds no stage, so nothing sanitised the frame: its NaN and Inf reached the EXR as they were,
    and a PNG's cast to integers printed numpy's warning (a process of its own: numpy's error state is per process)."""
    (tmp_path / "empty.json").write_text("{}")
    extra = ["--scene-referred", "--bit-depth", "float"] if output.endswith(".exr") else []
    done = subprocess.run([sys.executable, "-m", "torchgrade.cli", "grade", str(exr_dir / "BrightRingsNanInf.exr"), "-o",
                           str(tmp_path / output), "--config", str(tmp_path / "empty.json"), *extra],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == ""
    if output.endswith(".exr"):
        written = tg.io.read_exr(tmp_path / output)
        assert torch.isfinite(written).all() and written.abs().max() <= 65504.0


def test_a_tiny_file_asking_for_a_huge_canvas_is_refused_before_grading(tmp_path, capsys, monkeypatch):
    """364 bytes: a 1x1 data window in a 12000x12000 display window. Grading it ran the machine out of memory
    (`can't allocate` at 7.1 GB) after passing the read budget. It is refused from its header: no frame is read."""
    import OpenEXR

    from torchgrade.cli import common

    path = tmp_path / "bomb.exr"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "dataWindow": ((0, 0), (0, 0)), "displayWindow": ((0, 0), (11999, 11999))}
    OpenEXR.File(header, {"RGB": np.ones((1, 1, 3), np.float16)}).write(str(path))
    reads = []
    monkeypatch.setattr(common, "read_exr", lambda *args, **kwargs: reads.append(args))
    assert main(["grade", str(path), "-o", str(tmp_path / "out.png")]) == 2
    assert reads == []
    assert "displayWindow 12000x12000 needs about" in capsys.readouterr().err
    assert not (tmp_path / "out.png").exists()


def test_grading_memory_counts_at_most_as_many_frames_at_once_as_there_are(tmp_path):
    from torchgrade.cli.grade import GRADING_COPIES, check_grading_memory

    frame = tmp_path / "plate.exr"
    tg.io.write_exr(frame, torch.zeros(3, 10, 10))
    one_frame = GRADING_COPIES * 4 * 3 * 10 * 10  # float32 RGB buffers grading one frame holds
    check_grading_memory([frame], None, jobs=8, max_bytes=one_frame)  # one frame: graded alone, whatever --jobs
    check_grading_memory([frame, frame], None, jobs=8, max_bytes=2 * one_frame)
    with pytest.raises(ValueError, match=f"needs about {2 * one_frame} bytes .*2 at once"):
        check_grading_memory([frame, frame], None, jobs=8, max_bytes=2 * one_frame - 1)
