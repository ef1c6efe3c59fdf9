"""Frames as decoders and render targets hand them over: NCHW or NHWC, float32, float16, uint8 or uint16 in (integer
codes are sRGB, decoded to linear in the graph), any output encoding and layout out; each file against the PyTorch
look in 8-bit codes on onnxruntime and OpenVINO, at batch 1 and 4, at an odd size."""

import numpy as np
import onnx
import pytest
import torch

import torchgrade as tg
from torchgrade.cli import main
from torchgrade.onnx import export, session, verify
from torchgrade.onnx.verify import graph_nodes

from reference.onnx import hdr

LOOK = tg.PostFX(grade={"contrast": 15, "saturation": 10, "temperature": 8}, tonemap="aces").eval()
HEAD_LOOK = tg.PostFX(exposure={"speed": 1.5}, bloom={"intensity": 0.5, "max_iterations": 3}, tonemap="aces").eval()
"""Whole-frame stages before the per-pixel ones: the input is decoded before the strips, not in them."""
SHAPES = [(1, 3, 37, 53), (4, 3, 37, 53)]
CODE = 1.0
"""At most one 8-bit code from PyTorch: float32 differences between runtimes can cross half a code when rounding."""

CASES = {  # input dtype, input layout, output encoding, float dtype, output layout
    "uint8 NHWC -> srgb8 NHWC": (torch.uint8, "NHWC", "srgb8", torch.float32, "NHWC"),
    "uint8 NCHW -> linear NHWC": (torch.uint8, "NCHW", "linear", torch.float32, "NHWC"),
    "uint16 NHWC -> srgb16 NCHW": (torch.uint16, "NHWC", "srgb16", torch.float32, "NCHW"),
    "uint16 NCHW -> srgb half NHWC": (torch.uint16, "NCHW", "srgb", torch.float16, "NHWC"),
    "half NHWC -> linear half NHWC": (torch.float16, "NHWC", "linear", torch.float16, "NHWC"),
    "float NHWC -> srgb8 NCHW": (torch.float32, "NHWC", "srgb8", torch.float32, "NCHW"),
    "float NCHW -> srgb16 NHWC": (torch.float32, "NCHW", "srgb16", torch.float32, "NHWC"),
}
ELEMENTS = {torch.float32: "tensor(float)", torch.float16: "tensor(float16)", torch.uint8: "tensor(uint8)", torch.uint16: "tensor(uint16)"}


def frame_shape(layout):
    return ["batch", 3, "height", "width"] if layout == "NCHW" else ["batch", "height", "width", 3]


def scene(shape) -> torch.Tensor:
    """The test noise scaled into display range (an integer input holds [0, 1]), a few pixels above it."""
    return hdr(shape) / 20.0


@pytest.mark.parametrize("case", CASES)
def test_each_frame_format_matches_pytorch_in_8_bit_codes_on_both_runtimes(tmp_path, case):
    input_dtype, layout, output, float_dtype, output_layout = CASES[case]
    path = export(LOOK, tmp_path / "look.onnx", input_dtype=input_dtype, layout=layout, output=output, io_dtype=float_dtype,
                  output_layout=output_layout)
    runner = session(path)
    (port,), (out,) = runner.get_inputs(), runner.get_outputs()
    out_dtype = {"srgb8": torch.uint8, "srgb16": torch.uint16}.get(output, float_dtype)
    assert (port.type, port.shape, out.type, out.shape) == (ELEMENTS[input_dtype], frame_shape(layout), ELEMENTS[out_dtype],
                                                            frame_shape(output_layout))
    for runtime in tg.onnx.RUNTIMES:
        for shape in SHAPES:
            assert verify(LOOK, path, scene(shape), runtime, "f32", codes=True) <= CODE, (runtime, shape)


@pytest.mark.parametrize("strips", [True, False])
def test_a_look_with_whole_frame_stages_decodes_before_them(tmp_path, strips):
    path = export(HEAD_LOOK, tmp_path / "head.onnx", input_dtype=torch.uint8, layout="NHWC", output="srgb8", strips=strips)
    for runtime in tg.onnx.RUNTIMES:
        for shape in SHAPES:
            assert verify(HEAD_LOOK, path, scene(shape), runtime, "f32", codes=True) <= CODE, (runtime, shape, strips)
            video = (scene(shape), torch.linspace(0.0, 0.5, shape[0]), torch.tensor(0.1))
            assert verify(HEAD_LOOK, path, video, runtime, "f32", codes=True) <= CODE, (runtime, shape, strips)


def test_integer_codes_are_srgb_decoded_to_linear(tmp_path):
    """Code 118 is linear 0.1812 (mid grey), not 118/255 = 0.46: the graph decodes with the sRGB EOTF."""
    path = export(tg.ColorGrade(post_exposure=1.0), tmp_path / "grade.onnx", input_dtype=torch.uint8, layout="NHWC")
    codes = np.array([0, 10, 118, 255], dtype=np.uint8).reshape(1, 1, 4, 1).repeat(3, axis=3)
    output = session(path).run(None, {"image": codes})[0]
    linear = tg.color.transfer.srgb_to_linear(torch.tensor([0, 10, 118, 255]) / 255.0).numpy()
    np.testing.assert_allclose(output[0, 0, :, 1], 2.0 * linear, rtol=1e-5, atol=1e-7)


def test_a_per_pixel_look_decodes_and_encodes_in_the_strips(tmp_path):
    """Only the layout's transposes run on the whole frame: the sRGB decode and encode (each a power, written as Exp of a
    Log) are in the Scan's body, which begins with the codes' Cast and ends with the rounding's."""
    path = export(LOOK, tmp_path / "look.onnx", input_dtype=torch.uint8, layout="NHWC", output="srgb8")
    graph = onnx.load(str(path)).graph
    main_ops = [node.op_type for node in graph.node]
    scan, = [node for node in graph.node if node.op_type == "Scan"]
    body_ops = [node.op_type for node in graph_nodes(next(a.g for a in scan.attribute if a.name == "body"))]
    assert main_ops.count("Transpose") == 2 and not {"Pow", "Exp", "Log", "Cast"} & set(main_ops)
    assert body_ops[0] == "Cast" and body_ops[-2:] == ["Round", "Cast"] and "Pow" not in body_ops


def test_the_file_states_its_frame_format(tmp_path):
    path = export(LOOK, tmp_path / "look.onnx", input_dtype=torch.uint16, layout="nhwc", output="srgb8", output_layout="NCHW")
    fmt = tg.onnx.read_frame_format(tg.onnx.metadata(path))
    assert fmt == tg.onnx.frame_format(torch.uint16, "NHWC", "srgb8", torch.float32, "NCHW")
    image_doc = onnx.load(str(path)).graph.input[0].doc_string
    assert "sRGB-encoded" in image_doc and "uint16, 0-65535" in image_doc and "(batch, height, width, 3)" in image_doc


def test_export_command_takes_the_frame_format(tmp_path, capsys):
    config = tmp_path / "look.json"
    config.write_text('{"grade": {"contrast": 15}, "tonemap": "aces"}')
    out = tmp_path / "look.onnx"
    assert main(["export", "--config", str(config), "--out", str(out), "--width", "53", "--height", "37", "--input-dtype", "uint8",
                 "--layout", "nhwc", "--output", "srgb16"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "input uint8 NHWC, output srgb16 NHWC" in lines[0]
    errors = dict(part.rsplit(" ", 1) for part in lines[1].split("PyTorch: ")[1].split(", "))
    assert float(errors["onnxruntime"]) <= CODE and float(errors["openvino f32"]) <= CODE  # 8-bit codes
    assert [(i.name, i.type) for i in session(out).get_inputs()] == [("image", "tensor(uint8)")]
