"""Self-describing exports: doc strings and metadata, grading controls optional with the look's values as
defaults and clamped to their ranges, and the output encodings and float16 I/O on both runtimes."""

import json

import numpy as np
import onnx
import pytest
import torch

import torchgrade as tg
from torchgrade.onnx import export, metadata, session, verify

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


def test_grading_controls_are_optional_with_the_looks_values(look, with_inputs):
    runner = session(with_inputs)
    assert [i.name for i in runner.get_inputs()] == ["image"]
    for shape in [(1, 3, 9, 11), (3, 3, 16, 20)]:
        image = hdr(shape)
        output = runner.run(None, {"image": image.numpy()})[0]
        np.testing.assert_allclose(output, look(image).detach().numpy(), atol=STEP_TOLERANCE, rtol=0)
    assert verify(look, with_inputs, hdr((2, 3, 9, 11)), "openvino", "f32") <= STEP_TOLERANCE


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


def test_bad_output_options_raise(look, tmp_path):
    with pytest.raises(ValueError, match="output must be one of"):
        export(look, tmp_path / "x.onnx", output="rec2020")
    with pytest.raises(ValueError, match="io_dtype"):
        export(look, tmp_path / "x.onnx", io_dtype=torch.bfloat16)
