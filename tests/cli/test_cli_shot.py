"""``torchgrade grade`` on shots written by the test: frame order, eye adaptation carried across frames,
folders, globs and patterns, parallel jobs, LUTs, the output formats and the one-line errors."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import png
import pytest
import tifffile
import torch
from PIL import Image

import torchgrade as tg
from torchgrade.cli import main

EXPOSURE_LOOK = {"exposure": {"metering": "mean", "speed_to_light": 2.0, "speed_to_dark": 1.0}, "grade": {"contrast": 20}, "tonemap": "aces"}
FLAT_LOOK = {"grade": {"contrast": 20, "saturation": 10}, "tonemap": "neutral"}


@pytest.fixture
def plates(tmp_path):
    """Five 6x8 frames, numbered 8..12 (so a text sort would misorder them), growing brighter."""
    folder = tmp_path / "plates"
    folder.mkdir()
    generator = torch.Generator().manual_seed(0)
    frames = {}
    for number in (12, 8, 10, 9, 11):
        frames[number] = torch.rand(3, 6, 8, generator=generator) * (number - 7) ** 2
        tg.io.write_exr(folder / f"plate.{number}.exr", frames[number], half=False)
    return folder, [frames[n] for n in sorted(frames)]


def config_file(tmp_path, config):
    path = tmp_path / "look.json"
    path.write_text(json.dumps(config))
    return str(path)


def read_outputs(folder, pattern, count, first=8):
    return [tg.io.read_exr(folder / (pattern % n)) for n in range(first, first + count)]


def test_eye_adaptation_carries_across_the_shot_in_frame_order(plates, tmp_path):
    folder, frames = plates
    out = tmp_path / "out"
    out.mkdir()
    code = main(["grade", str(folder / "plate.%d.exr"), "-o", str(out / "graded.%04d.exr"), "--bit-depth", "float",
                 "--config", config_file(tmp_path, EXPOSURE_LOOK), "--fps", "12", "-q"])
    assert code == 0
    look = tg.PostFX.from_config(EXPOSURE_LOOK)  # the look's own stateful forward, frame after frame
    with torch.no_grad():
        expected = [look(frame.unsqueeze(0), dt=1 / 12)[0] for frame in frames]
    for got, want in zip(read_outputs(out, "graded.%04d.exr", 5), expected):
        torch.testing.assert_close(got, want, atol=1e-6, rtol=1e-5)
    fresh = [tg.PostFX.from_config(EXPOSURE_LOOK)(frame.unsqueeze(0))[0] for frame in frames]
    assert not torch.allclose(fresh[-1], expected[-1], atol=1e-3), "the last frame should still be adapting"


def test_folder_glob_pattern_and_files_name_the_same_frames(plates, tmp_path, capsys):
    folder, _ = plates
    shots = {
        "folder": [str(folder)],
        "glob": [str(folder / "plate.*.exr")],
        "pattern": [str(folder / "plate.%d.exr")],
        "files": [str(folder / f"plate.{n}.exr") for n in range(8, 13)],
    }
    results = {}
    for name, inputs in shots.items():
        (tmp_path / name).mkdir()
        assert main(["grade", *inputs, "-o", str(tmp_path / name / "f.%02d.exr"), "--config", config_file(tmp_path, EXPOSURE_LOOK), "-q"]) == 0
        results[name] = read_outputs(tmp_path / name, "f.%02d.exr", 5)
    for name in ("glob", "pattern", "files"):
        assert all(torch.equal(a, b) for a, b in zip(results["folder"], results[name])), name
    assert "grade: 5 frames, 8x6" in capsys.readouterr().out


def test_jobs_grade_in_parallel_what_one_job_grades(plates, tmp_path):
    folder, _ = plates
    config = config_file(tmp_path, FLAT_LOOK)
    for jobs in ("1", "3"):
        (tmp_path / jobs).mkdir()
        assert main(["grade", str(folder), "-o", str(tmp_path / jobs / "f.%d.png"), "--config", config, "-j", jobs, "-q"]) == 0
    for n in range(8, 13):
        assert np.array_equal(np.asarray(Image.open(tmp_path / "1" / f"f.{n}.png")), np.asarray(Image.open(tmp_path / "3" / f"f.{n}.png")))


def test_16_bit_png_and_tiff_agree_with_the_8_bit_png(plates, tmp_path):
    folder, _ = plates
    source, config = str(folder / "plate.10.exr"), config_file(tmp_path, FLAT_LOOK)
    for name, depth in (("8.png", "8"), ("16.png", "16"), ("16.tif", "16"), ("float.tif", "float"), ("float.exr", "float")):
        assert main(["grade", source, "-o", str(tmp_path / name), "--config", config, "--bit-depth", depth]) == 0
    eight = np.asarray(Image.open(tmp_path / "8.png")).astype(np.float64)
    width, height, rows, info = png.Reader(filename=str(tmp_path / "16.png")).asDirect()
    sixteen = np.vstack([np.asarray(row, dtype=np.uint16) for row in rows]).reshape(height, width, 3)
    assert info["bitdepth"] == 16 and np.abs(sixteen / 257.0 - eight).max() <= 0.5 + 1e-9
    assert np.array_equal(tifffile.imread(tmp_path / "16.tif"), sixteen)
    linear = tg.io.read_exr(tmp_path / "float.exr").permute(1, 2, 0).numpy()
    assert np.array_equal(tifffile.imread(tmp_path / "float.tif"), linear)


def test_scene_referred_output_stops_before_tone_mapping(plates, tmp_path):
    folder, frames = plates
    look = {"grade": {"contrast": 20, "post_exposure": 1.0}, "tonemap": "aces"}
    out = tmp_path / "scene.exr"
    assert main(["grade", str(folder / "plate.12.exr"), "-o", str(out), "--config", config_file(tmp_path, look),
                 "--scene-referred", "--bit-depth", "float"]) == 0
    expected = tg.ColorGrade(contrast=20, post_exposure=1.0)(frames[-1].unsqueeze(0))[0]
    torch.testing.assert_close(tg.io.read_exr(out), expected, atol=1e-5, rtol=1e-5)
    assert expected.max() > 1.0, "scene-referred values should keep their range"


def test_lut_grades_like_the_look_it_was_baked_from(plates, tmp_path):
    # plate 8 stays below 1: a .cube read back today departs from its look above 1 (a LUT3D domain matter, not the CLI's)
    folder, _ = plates
    config, cube = config_file(tmp_path, FLAT_LOOK), tmp_path / "look.cube"
    assert main(["bake", "-o", str(cube), "--config", config, "--size", "33", "--accept-error"]) == 0  # the test bounds the error itself
    assert main(["grade", str(folder / "plate.8.exr"), "-o", str(tmp_path / "lut.exr"), "--lut", str(cube)]) == 0
    assert main(["grade", str(folder / "plate.8.exr"), "-o", str(tmp_path / "look.exr"), "--config", config]) == 0
    torch.testing.assert_close(tg.io.read_exr(tmp_path / "lut.exr"), tg.io.read_exr(tmp_path / "look.exr"), atol=1e-2, rtol=0)  # a 33³ lattice


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["{empty}", "-o", "{tmp}/x.%04d.png"], "no EXR files in folder"),
        (["{plates}/nothing.%04d.exr", "-o", "{tmp}/x.%04d.png"], "no frames match"),
        (["{plates}", "-o", "{tmp}/x.png"], "need an output pattern"),
        (["{plates}", "-o", "{tmp}/x.%d.png", "--config", "{exposure}", "-j", "2"], "--jobs needs a look without eye adaptation"),
        (["{plates}", "-o", "{tmp}/x.%d.png", "--scene-referred"], "--scene-referred values exceed 1"),
        (["{plates}", "-o", "{tmp}/x.%d.png", "--bit-depth", "float"], "does not fit .png"),
        (["{plates}", "-o", "{tmp}/x.%d.png", "--histogram-percent", "100", "0"], "give it with --metering histogram"),
        (["{plates}", "-o", "{tmp}/x.%d.png", "--metering", "histogram", "--histogram-percent", "100", "0"],
         "low_percent ([100.0]) must be below high_percent ([0.0])"),
        (["{plates}", "-o", "{tmp}/x.%d.png", "--metering", "histogram", "--histogram-percent", "40", "40"],
         "low_percent ([40.0]) must be below high_percent ([40.0])"),
    ],
)
def test_bad_shots_fail_with_one_line(plates, tmp_path, capsys, arguments, message):
    folder, _ = plates
    (tmp_path / "empty").mkdir()
    names = {"empty": tmp_path / "empty", "tmp": tmp_path, "plates": folder, "exposure": config_file(tmp_path, EXPOSURE_LOOK)}
    assert main(["grade", *[a.format(**names) for a in arguments]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not list(tmp_path.glob("x.*"))


def test_version(capsys):
    with pytest.raises(SystemExit) as exit:
        main(["--version"])
    assert exit.value.code == 0 and capsys.readouterr().out.strip() == f"torchgrade {tg.__version__}"


SLOW_SHOT = """
import sys, time
from torchgrade.shots import frames
graded = frames.render_frame
begun = []
def slowly(*args, **kwargs):  # every frame after the first seconds long, so that a signal lands mid-shot on a busy machine
    begun.append(None)
    time.sleep(0.2 if len(begun) == 1 else 3.0)
    return graded(*args, **kwargs)
frames.render_frame = slowly
from torchgrade.cli import main
sys.exit(main(sys.argv[1:]))
"""


def start_shot(tmp_path, count: int, *flags) -> tuple:
    """A ``grade`` of ``count`` plates to ``out/g.%04d.exr`` in a child process, each frame taking a while, and the
    child once its first frame is written."""
    folder = tmp_path / "plates"
    folder.mkdir()
    for number in range(1, count + 1):
        tg.io.write_exr(folder / f"plate.{number:04d}.exr", torch.rand(3, 6, 8) * number, half=False)
    (tmp_path / "out").mkdir()
    command = [sys.executable, "-c", SLOW_SHOT, "grade", str(folder), "-o", str(tmp_path / "out" / "g.%04d.exr"),
               "--scene-referred", "--contrast", "10", "--quiet", *flags]
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,  # as a terminal starts it:
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # a background job ignores SIGINT
    deadline = time.monotonic() + 900  # a guard against a child that never starts, not a measure: a busy machine's
    while not list((tmp_path / "out").glob("g.*.exr")) and child.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)  # first import of torch in a fresh environment has taken minutes
    assert list((tmp_path / "out").glob("g.*.exr")), "the shot wrote no frame before it was to be interrupted"
    return child, tmp_path / "out"


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_ctrl_c_stops_a_shot_with_one_line_and_status_130_and_leaves_no_temporary(tmp_path, jobs):
    """Ctrl-C printed a traceback (and with --jobs the frames queued were all graded first): one line, status 130, the
    frames written whole, no hidden temporary, and the frames not begun not graded."""
    child, out = start_shot(tmp_path, 40, "--jobs", jobs)
    child.send_signal(signal.SIGINT)
    _, stderr = child.communicate(timeout=300)
    assert child.returncode == 130 and stderr.splitlines() == ["torchgrade grade: interrupted"], stderr[-2000:]
    written = sorted(out.glob("g.*.exr"))
    assert 1 <= len(written) < 40 and not [p.name for p in out.iterdir() if p.name.startswith(".")]
    for frame in written:
        assert tg.io.read_exr(frame).shape == (3, 6, 8)


KILLED_WRITE = """
import pathlib, sys, time
from torchgrade.io.atomic import atomic_write
def stall(temporary):
    pathlib.Path(temporary).write_bytes(b"half a frame")
    time.sleep(600)  # killed here
atomic_write(sys.argv[1], stall)
"""


def test_the_next_run_removes_the_temporary_a_killed_shot_left_and_no_other(plates, tmp_path):
    """A write killed with SIGKILL left ``.g.0010.exr.8ff158ee.exr`` that no later run removed: a grade of the frames
    it writes removes their temporaries; another file's temporary (a write in flight elsewhere) stays."""
    folder, _ = plates
    out = tmp_path / "out"
    out.mkdir()
    child = subprocess.Popen([sys.executable, "-c", KILLED_WRITE, str(out / "g.0010.exr")])
    deadline = time.monotonic() + 120  # a guard against a child that never starts, not a measure
    while not [p for p in out.iterdir() if p.name.startswith(".")] and time.monotonic() < deadline:
        time.sleep(0.01)
    child.send_signal(signal.SIGKILL)
    child.wait(timeout=60)
    left = [p.name for p in out.iterdir()]
    assert len(left) == 1 and left[0].startswith(".g.0010.exr.")  # what SIGKILL leaves
    (out / ".g.0099.exr.0bc52090.exr").write_bytes(b"another run's frame")
    (out / ".notes").write_text("the user's")
    assert main(["grade", str(folder), "-o", str(out / "g.%04d.exr"), "--scene-referred", "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [".g.0099.exr.0bc52090.exr", ".notes", *(f"g.{n:04d}.exr" for n in range(8, 13))]
