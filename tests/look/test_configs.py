"""Look configs as untrusted input: round trips of per-sample looks, JSON types, bounded reading, the CLI's one line."""

import json
import os

import pytest
import torch

import torchgrade as tg
from torchgrade.cli import main
from torchgrade.base.config import MAX_CONFIG_BYTES, MAX_CONFIG_DEPTH, json_depth, load_config
from torchgrade.grading.curves import MAX_CURVE_POINTS


def per_sample_look() -> tg.PostFX:
    return tg.PostFX(
        bloom=tg.Bloom(intensity=torch.tensor([0.5, 1.0]), max_iterations=3),
        grade=tg.ColorGrade(contrast=torch.tensor([10.0, 20.0]), color_filter=torch.tensor([[1.0, 0.5, 0.5], [1.0, 1.0, 1.0]]),
                            channel_mixer=torch.eye(3).expand(2, 3, 3) * torch.tensor([1.0, 0.9]).view(2, 1, 1)),
        tonemap=tg.ToneMap("reinhard_extended", white_point=torch.tensor([4.0, 8.0])),
    )


def test_per_sample_look_round_trips_through_json():
    look = per_sample_look()
    back = tg.PostFX.from_config(json.loads(json.dumps(look.to_config())))
    image = torch.rand(2, 3, 16, 16) * 4.0
    torch.testing.assert_close(back(image), look(image), atol=0, rtol=0)
    assert isinstance(back.grade.contrast, torch.Tensor) and back.grade.contrast.shape == (2,)


@pytest.mark.parametrize("stage", [
    tg.ColorGrade(contrast=torch.tensor([10.0, -30.0]), color_filter=torch.tensor([[1.0, 0.8, 0.6], [0.6, 0.8, 1.0]])),
    tg.ToneMap("reinhard_extended", white_point=torch.tensor([4.0, 8.0])),
    tg.Bloom(intensity=torch.tensor([0.5, 2.0])),
    tg.PrimaryGrade(exposure=torch.tensor([[0.5, 0.0, -0.5], [0.0, 0.2, 0.0]])),
], ids=lambda stage: type(stage).__name__)
def test_a_single_stage_with_per_sample_controls_round_trips_through_json(stage):
    config = json.loads(json.dumps(stage.to_config()))
    back = type(stage).from_config(config)
    for name, value in stage.params().items():
        if isinstance(value, torch.Tensor):
            restored = getattr(back, name)
            assert isinstance(restored, torch.Tensor) and torch.equal(restored, value), name
    image = torch.rand(2, 3, 16, 16) * 4.0
    torch.testing.assert_close(back(image), stage(image), atol=0, rtol=0)


def test_each_sample_of_a_loaded_look_is_that_sample_graded_alone():
    """Invariant: sample i of a per-sample look equals the look built from sample i's scalars."""
    back = tg.PostFX.from_config(json.loads(json.dumps({"grade": {"contrast": [10, -30], "saturation": [0, 40]}})))
    image = torch.rand(2, 3, 8, 8)
    for i, (contrast, saturation) in enumerate([(10, 0), (-30, 40)]):
        alone = tg.ColorGrade(contrast=contrast, saturation=saturation)
        torch.testing.assert_close(back(image)[i : i + 1], alone(image[i : i + 1]), atol=1e-6, rtol=0)


def test_colours_and_matrices_given_once_stay_plain_values():
    grade = tg.PostFX.from_config({"grade": {"color_filter": [1.0, 0.5, 0.5], "channel_mixer": [[1, 0, 0], [0, 1, 0], [0, 0, 0.5]]}}).grade
    assert not isinstance(grade.color_filter, torch.Tensor) and not isinstance(grade.channel_mixer, torch.Tensor)


BAD_VALUES = {
    "a boolean for a number": ({"grade": {"contrast": True}}, "grade.contrast"),
    "a string for a number": ({"grade": {"contrast": "10"}}, "grade.contrast"),
    "a string in a colour": ({"grade": {"color_filter": [1, "a", 1]}}, "grade.color_filter"),
    "a boolean in a list": ({"grade": {"contrast": [True, 10]}}, "grade.contrast"),
    "an empty list": ({"grade": {"contrast": []}}, "grade.contrast"),
    "an empty nested list": ({"grade": {"contrast": [[[]]]}}, "grade.contrast"),
    "a ragged list": ({"grade": {"color_filter": [[1, 1, 1], [1, 1]]}}, "grade.color_filter"),
    "an object for a number": ({"grade": {"contrast": {}}}, "grade.contrast"),
    "a number for a flag": ({"grade": {"aces": 1}}, "grade.aces"),
    "a number for a mode": ({"tonemap": {"mode": 3}}, "tonemap.mode"),
    "a list for a mode": ({"tonemap": {"mode": ["aces"]}}, "tonemap.mode"),
    "a float for an integer": ({"dither": {"size": 4.0}}, "dither.size"),
    "dither size above 4096": ({"dither": {"size": 4097}}, "dither.size"),
    "dither size 0": ({"dither": {"size": 0}}, "dither.size"),
    "too many curve points": ({"grade": {"curve_master": [[i / 999999, i / 999999] for i in range(10**6)]}}, "grade.curve_master"),
    "a number for a curve": ({"grade": {"curve_master": 5}}, "grade.curve_master"),
    "an integer beyond 64 bits": ({"grade": {"contrast": [10**30, 1]}}, "grade.contrast"),
}


@pytest.mark.parametrize("name", sorted(BAD_VALUES))
def test_wrong_types_and_bounds_are_refused_at_load_naming_the_key(name):
    config, key = BAD_VALUES[name]
    with pytest.raises(ValueError, match=key.replace(".", r"\.")):
        tg.PostFX.from_config(config)


def test_a_curve_of_the_largest_size_loads_and_one_more_point_does_not():
    points = [[i / (MAX_CURVE_POINTS - 1), i / (MAX_CURVE_POINTS - 1)] for i in range(MAX_CURVE_POINTS)]
    tg.PostFX.from_config({"grade": {"curve_master": points}})
    longer = [[i / MAX_CURVE_POINTS, i / MAX_CURVE_POINTS] for i in range(MAX_CURVE_POINTS + 1)]
    with pytest.raises(ValueError, match="at most 256"):
        tg.PostFX.from_config({"grade": {"curve_master": longer}})


def test_json_depth_counts_brackets_outside_strings():
    assert json_depth(b"{}") == 1
    assert json_depth(b'{"a": "[[[{{{", "b": [[1, "\\"]"]]}') == 3  # an escaped quote does not end the string
    assert json_depth(b"1") == 0


def write(folder, name: str, text) -> str:
    path = folder / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return str(path)


def bad_config_files(folder) -> dict:
    """Each bad config file, and a word its error names."""
    return {
        "deep": (write(folder, "deep.json", '{"grade": ' + "[" * 100_000 + "]" * 100_000 + "}"), "levels deep"),
        "large": (write(folder, "large.json", b" " * (MAX_CONFIG_BYTES + 1) + b"{}"), "larger than"),
        "directory": (str(folder), "not a regular file"),
        "device": ("/dev/zero", "not a regular file"),
        "not json": (write(folder, "text.json", "grade: contrast 20"), "not valid JSON"),
        "nan": (write(folder, "nan.json", '{"grade": {"contrast": NaN}}'), "NaN"),
        "not an object": (write(folder, "list.json", "[1, 2]"), "JSON object"),
        "not utf-8": (write(folder, "binary.json", b'{"grade": "\xff"}'), "not valid JSON"),
        "wrong type": (write(folder, "type.json", '{"grade": {"contrast": "high"}}'), "grade.contrast"),
        "huge number": (write(folder, "huge.json", '{"bloom": {"intensity": ' + "9" * 400 + "}}"), "bloom.intensity"),
        "missing": (str(folder / "missing.json"), "missing.json"),
    }


def test_bad_config_files_raise_value_error_or_os_error_naming_the_problem(tmp_path):
    for name, (path, words) in bad_config_files(tmp_path).items():
        error = ValueError if name != "missing" else OSError
        with pytest.raises(error, match=words):
            tg.PostFX.from_config(path)


def test_the_depth_bound_admits_every_look_to_config_writes(tmp_path):
    path = write(tmp_path, "look.json", json.dumps(per_sample_look().to_config()))
    assert json_depth(open(path, "rb").read()) <= MAX_CONFIG_DEPTH
    assert load_config(path) == json.loads(open(path).read())


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_a_named_pipe_is_refused_without_waiting_for_a_writer(tmp_path):
    fifo = tmp_path / "look.json"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="not a regular file"):
        load_config(fifo)


@pytest.mark.parametrize("command", ["bake", "export"])
def test_the_cli_prints_one_line_and_status_2_for_every_bad_config(tmp_path, capsys, command):
    for name, (path, words) in bad_config_files(tmp_path).items():
        output = str(tmp_path / ("out.cube" if command == "bake" else "out.onnx"))
        assert main([command, "--config", path, "-o", output]) == 2, name
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.count("\n") == 1, name
        assert captured.err.startswith(f"torchgrade {command}: error:") and words in captured.err, name


def _number_controls():
    """Every number control of every configurable stage, with the mode or style that has it."""
    from torchgrade.look.slots import STAGES
    from torchgrade.grading.primary import STYLE_CONTROLS
    from torchgrade.tonemap import TONE_MAPPERS

    for stage, cls in STAGES.items():
        tables = [({"lut": 2} if stage == "look_lut" else {}, cls.controls)]  # a look LUT needs its table (here 2³)
        if stage == "tonemap":
            tables = [({"mode": mode}, entry.controls) for mode, entry in TONE_MAPPERS.items()]
        for setting, table in tables:
            for name, control in table.items():
                if control.kind not in ("number", "int") or name in ("seed",):
                    continue
                if stage == "primary":
                    setting = {"style": next(s for s, names in STYLE_CONTROLS.items() if name in names)}
                yield pytest.param(stage, setting, name, control, id=f"{stage}.{setting.get('mode', '')}{name}")


@pytest.mark.parametrize("stage, setting, name, control", list(_number_controls()))
def test_a_json_number_too_large_for_a_float_is_a_value_error_naming_the_key(stage, setting, name, control):
    """JSON numbers have no size limit: a 400-digit integer in any control raised a bare OverflowError."""
    huge = int("9" * 400)
    shape = torch.as_tensor(control.default if control.default is not None else 0.0).shape
    value = torch.full(shape, 0.0).tolist() if shape else 0
    value = huge if not shape else [huge] + value[1:] if len(shape) == 1 else [[huge, *value[0][1:]], *value[1:]]
    with pytest.raises(ValueError, match=rf"{stage}\.{name} must be"):
        tg.PostFX.from_config({stage: {**setting, name: value}})
