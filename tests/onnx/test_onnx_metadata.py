"""Self-describing exports: doc strings and metadata, grading controls as optional inputs (listed, no runtime warning)
with the look's values as defaults and clamped to their ranges, adaptation inputs a still leaves out, only the opset
domains used, and the output encodings and float16 I/O on both runtimes."""

import json

import numpy as np
import onnx
import pytest
import torch

import torchgrade as tg
from torchgrade.onnx import export, metadata, session, verify
from torchgrade.onnx.verify import graph_nodes

from reference.onnx import STEP_TOLERANCE, TOLERANCE, hdr

LOOK = {"grade": {"contrast": 15, "saturation": 10, "temperature": 8}, "tonemap": "aces"}


@pytest.fixture(scope="module")
def look():
    return tg.PostFX.from_config(LOOK).eval()


@pytest.fixture(scope="module")
def with_inputs(look, tmp_path_factory):
    return export(look, tmp_path_factory.mktemp("meta") / "inputs.onnx", grade_inputs=True)


def test_the_file_describes_itself(look, with_inputs):
    model = onnx.load(str(with_inputs))
    props = metadata(with_inputs)
    assert props["torchgrade.version"] == tg.__version__ and props["torchgrade.output"] == "linear"
    rebuilt = tg.PostFX.from_config(json.loads(props["torchgrade.config"]))
    image = hdr((1, 3, 8, 8))
    torch.testing.assert_close(rebuilt(image), look(image))
    controls = json.loads(props["torchgrade.grade_inputs"])
    assert controls["contrast"] == {"range": [-100.0, 100.0], "default": 15.0}
    assert "Rec.709" in model.doc_string or "Rec.709" in props["color_space.input"]
    assert all(graph_input.doc_string for graph_input in model.graph.input)
    assert all(graph_output.doc_string for graph_output in model.graph.output)


def test_the_config_is_written_under_torchgrade_config_and_read_under_the_former_key_too(look, with_inputs, tmp_path):
    written = {prop.key for prop in onnx.load(str(with_inputs)).metadata_props}
    assert "torchgrade.config" in written and "torchgrade.base.config" not in written
    model = onnx.load(str(with_inputs))
    for prop in model.metadata_props:  # as a file exported while the key was "torchgrade.base.config" holds it
        if prop.key == "torchgrade.config":
            prop.key = "torchgrade.base.config"
    onnx.save(model, str(tmp_path / "former.onnx"))
    props = metadata(tmp_path / "former.onnx")
    assert "torchgrade.base.config" not in props
    assert tg.PostFX.from_config(json.loads(props["torchgrade.config"])).to_config() == look.to_config()


def test_grading_controls_are_optional_inputs_with_the_looks_values(look, with_inputs, capfd):
    """Listed by get_inputs() (what a server config is written from), left out at will, and no runtime warning:
    as initializers of the inputs' names they were listed by get_overridable_initializers() alone, 20 warnings a session."""
    import onnxruntime

    capfd.readouterr()
    runner = onnxruntime.InferenceSession(str(with_inputs), providers=["CPUExecutionProvider"])
    assert capfd.readouterr().err == ""
    assert [(i.name, i.type) for i in runner.get_inputs()] == [("image", "tensor(float)")] + [
        (name, "optional(tensor(float))") for name in tg.onnx.GRADE_INPUTS]
    assert runner.get_overridable_initializers() == []
    for shape in [(1, 3, 9, 11), (3, 3, 16, 20)]:
        image = hdr(shape)
        output = runner.run(None, {"image": image.numpy()})[0]
        np.testing.assert_allclose(output, look(image).detach().numpy(), atol=STEP_TOLERANCE, rtol=0)
    assert verify(look, with_inputs, hdr((2, 3, 9, 11)), "openvino", "f32") <= STEP_TOLERANCE


def test_plain_inputs_for_runtimes_without_optional_types(look, tmp_path):
    """optional_inputs=False: every input a plain tensor (OpenVINO and TensorRT read no optional type), fed each call."""
    path = export(look, tmp_path / "plain.onnx", grade_inputs=True, optional_inputs=False)
    model = onnx.load(str(path))
    assert not any(node.op_type.startswith("Optional") for node in model.graph.node)
    assert all(graph_input.type.HasField("tensor_type") for graph_input in model.graph.input)
    runner = session(path)
    with pytest.raises(ValueError, match="Required inputs"):
        runner.run(None, {"image": hdr((1, 3, 9, 11)).numpy()})
    for runtime in tg.onnx.RUNTIMES:
        assert verify(look, path, hdr((2, 3, 9, 11)), runtime, "f32") <= STEP_TOLERANCE


def test_one_control_per_sample_the_rest_default(with_inputs):
    image = hdr((2, 3, 9, 11))
    contrast = np.array([500.0, -40.0], dtype=np.float32)  # 500 is outside [-100, 100]: clamped
    output = session(with_inputs).run(None, {"image": image.numpy(), "contrast": contrast})[0]
    for sample, value in enumerate([100.0, -40.0]):
        expected = tg.PostFX.from_config({**LOOK, "grade": {**LOOK["grade"], "contrast": value}})(image[sample : sample + 1])
        np.testing.assert_allclose(output[sample : sample + 1], expected.detach().numpy(), atol=STEP_TOLERANCE, rtol=0)


@pytest.mark.parametrize("output, tolerance", [("srgb", TOLERANCE), ("srgb8", 1.0)])
def test_srgb_outputs_on_both_runtimes(look, tmp_path, output, tolerance):
    """8-bit output: at most one code from PyTorch rounded (float32 differences can cross a half code)."""
    path = export(look, tmp_path / f"{output}.onnx", output=output)
    assert onnx.load(str(path)).graph.output[0].type.tensor_type.elem_type == (
        onnx.TensorProto.UINT8 if output == "srgb8" else onnx.TensorProto.FLOAT)
    for runtime in tg.onnx.RUNTIMES:
        for shape in [(1, 3, 9, 11), (2, 3, 16, 20)]:
            assert verify(look, path, hdr(shape), runtime, "f32") <= tolerance, (runtime, shape)


def test_float16_input_and_output(look, tmp_path):
    """float16 I/O, float32 inside: the error is the float16 rounding of the input and the output."""
    path = export(look, tmp_path / "half.onnx", io_dtype=torch.float16)
    model = onnx.load(str(path))
    assert model.graph.input[0].type.tensor_type.elem_type == onnx.TensorProto.FLOAT16
    assert model.graph.output[0].type.tensor_type.elem_type == onnx.TensorProto.FLOAT16
    image = hdr((2, 3, 9, 11)).half()
    expected = look(image.float()).detach().numpy()
    for runtime in tg.onnx.RUNTIMES:
        output = session(path, runtime, "f32").run(None, {"image": image.numpy()})[0]
        assert output.dtype == np.float16
        np.testing.assert_allclose(output.astype(np.float32), expected, atol=2e-3, rtol=0)


STILL_LOOK = {"exposure": {"speed": 1.5}, "grade": {"contrast": 15}, "tonemap": "aces"}


@pytest.mark.parametrize("optional_inputs", [True, False])
def test_a_still_needs_no_adaptation_inputs_and_video_keeps_feeding_them(tmp_path, optional_inputs):
    """adapted and dt default to instant adaptation; verify takes the image alone (it raised KeyError: 'adapted')."""
    look = tg.PostFX.from_config(STILL_LOOK).eval()
    path = export(look, tmp_path / "still.onnx", optional_inputs=optional_inputs)
    image = hdr((4, 3, 37, 53))
    for runtime in tg.onnx.RUNTIMES:
        assert verify(look, path, image, runtime, "f32") <= TOLERANCE * 60, runtime  # scene-referred: peak ~60
        video = (image, torch.tensor([0.0, 0.3, 1.0, 5.0]), torch.tensor(0.1))
        assert verify(look, path, video, runtime, "f32") <= TOLERANCE * 60, runtime
    if optional_inputs:
        runner = session(path)
        still, adapted = runner.run(None, {"image": image.numpy()})
        with torch.no_grad():
            expected, expected_adapted = look.frame(image, None, 0.0)
        np.testing.assert_allclose(still, expected.numpy(), atol=TOLERANCE * 60, rtol=0)
        np.testing.assert_allclose(adapted, expected_adapted.numpy(), rtol=1e-5)


def test_verify_names_a_wrong_input(tmp_path):
    look = tg.PostFX.from_config(STILL_LOOK).eval()
    path = export(look, tmp_path / "still.onnx")
    image = hdr((2, 3, 9, 11))
    with pytest.raises(ValueError, match=r"takes \(image,\) or \(image, adapted, dt\); got 2 inputs"):
        verify(look, path, (image, torch.zeros(2)))
    with pytest.raises(ValueError, match=r"adapted must have shape \(2,\)"):
        verify(look, path, (image, torch.zeros(3), torch.tensor(0.1)))
    with pytest.raises(ValueError, match=r"image must have shape \(\.\.\., 3, H, W\) with 3 colour channels, got \(2, 9, 11, 3\)"):
        verify(look, path, image.permute(0, 2, 3, 1))
    with pytest.raises(TypeError, match="floating-point"):
        verify(look, path, (image * 255).to(torch.uint8))
    tone = tg.ToneMap("aces")
    with pytest.raises(ValueError, match="image alone"):
        verify(tone, export(tone, tmp_path / "tone.onnx"), (image, torch.zeros(2), torch.tensor(0.1)))


def test_only_the_opset_domains_used_are_declared(with_inputs):
    """onnxruntime's optimised file declared nine domains (com.microsoft, org.pytorch.aten, ...) for standard nodes."""
    model = onnx.load(str(with_inputs))
    assert {node.domain for node in graph_nodes(model.graph)} == {""}
    assert [(opset.domain, opset.version) for opset in model.opset_import] == [("", 17)]


def test_bad_output_options_raise(look, tmp_path):
    with pytest.raises(ValueError, match="output must be one of"):
        export(look, tmp_path / "x.onnx", output="rec2020")
    with pytest.raises(ValueError, match="io_dtype"):
        export(look, tmp_path / "x.onnx", io_dtype=torch.bfloat16)
    with pytest.raises(ValueError, match="input_dtype must be one of"):
        export(look, tmp_path / "x.onnx", input_dtype=torch.int8)
    with pytest.raises(TypeError, match="input_dtype must be a torch.dtype"):
        export(look, tmp_path / "x.onnx", input_dtype="uint8")
    with pytest.raises(ValueError, match="layout must be one of"):
        export(look, tmp_path / "x.onnx", layout="CHW")
    assert not list(tmp_path.iterdir())
