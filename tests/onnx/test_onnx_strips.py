"""Export forms for speed: the per-pixel stages in a ``Scan`` over strips of rows, on onnxruntime and OpenVINO at
shapes whose heights are not a whole number of strips, and powers without ``Where`` guards or ``Pow`` nodes."""

import collections
import json
import math
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper

import torchgrade as tg
from torchgrade.base.planes import bounded_pow
from torchgrade.color.transfer import safe_pow
from torchgrade.onnx import export, session, verify
from torchgrade.onnx.verify import graph_nodes
from torchgrade.onnx.strips import scan_strips
from torchgrade.onnx.strips import DOMAIN
from torchgrade.onnx.strips import SCAN_STRIP_PIXELS as STRIP_PIXELS
from torchgrade.color import unity_to_aces
from torchgrade.tonemap.aces1.rrt import _red_hue_distance, _yc, cubic_basis_hue_weight, smoothstep_hue_weight

from reference.onnx import TOLERANCE

CINEMATIC = json.loads((Path(__file__).resolve().parents[2] / "export" / "looks" / "cinematic.json").read_text())
SHAPES = [(1, 3, 17, 23), (1, 3, 333, 517), (2, 3, 130, 1100)]
"""One strip; two strips of 167 rows over 333 (one row of padding); three strips of 44 rows over 130."""


def frame(shape) -> torch.Tensor:
    """The demo scene: on the test noise, many pixels sit on the sharp corners of this look, where the whole-frame graph
    is 1.2e-4 (onnxruntime, 333x517) and 4.7e-4 (OpenVINO, 2x130x1100) off PyTorch too."""
    return tg.scene.demo_scene(*shape[2:]).expand(shape).contiguous()


def ops(path) -> collections.Counter:
    return collections.Counter(node.op_type for node in graph_nodes(onnx.load(str(path)).graph))


def strip_heights(height: int, width: int, batch: int = 1) -> int:
    """The strip height the graph should pick, from the formula in :mod:`torchgrade.onnx.strips`."""
    most = min(height, max(1, STRIP_PIXELS // (batch * width)))
    count = -(-height // most)
    return -(-height // count)


@pytest.mark.parametrize("shape", SHAPES)
def test_each_strip_sees_its_own_rows(shape):
    """A body that writes each strip's height and its first row's values: the strips tile the frame in order."""
    node = helper.make_node
    body = [
        node("Strips", ["image"], ["strip"], domain=DOMAIN),
        node("Shape", ["strip"], ["shape"]),
        node("Gather", ["shape", "two"], ["rows"], axis=0),
        node("Cast", ["rows"], ["rows_f"], to=TensorProto.FLOAT),
        node("Mul", ["strip", "zero"], ["zeros"]),
        node("Add", ["zeros", "rows_f"], ["heights"]),
        node("StripsEnd", ["heights"], ["output"], domain=DOMAIN),
    ]
    graph = helper.make_graph(
        body, "heights", [helper.make_tensor_value_info("image", TensorProto.FLOAT, ["n", 3, "h", "w"])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, ["n", 3, "h", "w"])],
        [onnx.numpy_helper.from_array(np.array(2, np.int64), "two"), onnx.numpy_helper.from_array(np.array(0.0, np.float32), "zero")],
        value_info=[helper.make_tensor_value_info("strip", TensorProto.FLOAT, None)])  # as the exporter types a marker
    model = scan_strips(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17), helper.make_opsetid(DOMAIN, 1)]))
    onnx.checker.check_model(model)
    assert [n.op_type for n in model.graph.node].count("Scan") == 1
    image = np.random.default_rng(0).random(shape, dtype=np.float32)
    import onnxruntime

    output = onnxruntime.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"image": image})[0]
    assert output.shape == shape
    assert np.all(output == strip_heights(shape[2], shape[3], shape[0]))


@pytest.fixture(scope="module")
def per_pixel_look(tmp_path_factory):
    """The cinematic look's grade and tone map (per pixel, the Scan's body), exported with and without strips."""
    look = tg.PostFX.from_config({"grade": CINEMATIC["grade"], "tonemap": CINEMATIC["tonemap"]}).eval()
    folder = tmp_path_factory.mktemp("strips")
    return look, export(look, folder / "strips.onnx"), export(look, folder / "whole.onnx", strips=False)


def test_per_pixel_stages_run_in_a_scan_and_match_pytorch_on_both_runtimes(per_pixel_look):
    look, path, whole = per_pixel_look
    assert ops(path)["Scan"] == 1 and ops(whole)["Scan"] == 0
    main = len(onnx.load(str(path)).graph.node)
    assert main < 30 < sum(ops(path).values()) - main  # the main graph only cuts and joins strips
    for shape in SHAPES:
        image = frame(shape)
        with torch.no_grad():
            peak = max(1.0, float(look(image).abs().max()))
        for runtime, precision in (("onnxruntime", None), ("openvino", "f32")):
            assert verify(look, path, image, runtime, precision) / peak <= TOLERANCE, (shape, runtime)


def test_strips_and_whole_frame_graphs_agree(per_pixel_look):
    _, path, whole = per_pixel_look
    image = tg.scene.demo_scene(333, 517).numpy()
    outputs = [session(p).run(None, {"image": image})[0] for p in (path, whole)]
    np.testing.assert_allclose(outputs[0], outputs[1], atol=1e-6, rtol=1e-6)


def test_full_look_with_encoded_output_runs_its_tail_in_strips(tmp_path):
    """Exposure and bloom stay on the whole frame; grade, tone map and the 8-bit encoding run in strips."""
    look = tg.PostFX.from_config(CINEMATIC).eval()
    path = export(look, tmp_path / "look.onnx", output="srgb8")
    assert ops(path)["Scan"] == 1
    image = tg.scene.demo_scene(333, 517)
    inputs = tg.onnx.graph_inputs(look, image)
    for runtime, precision in (("onnxruntime", None), ("openvino", "f32")):
        assert verify(look, path, inputs, runtime, precision) <= 1.0, runtime  # 8-bit codes: rounding only


class _Powers(torch.nn.Module):
    """The guarded powers, and plain powers of each exponent form the export treats apart."""

    def forward(self, x):
        return torch.cat([safe_pow(x, 1.0 / 2.2), safe_pow(x, 2.2), bounded_pow(x, 3.5), x.abs() ** 2, x ** 3,
                          x.abs() ** 0.5, x.abs() ** 1.7, x ** 4, x ** 0.0, x ** 1.0], dim=1)


def test_powers_export_without_where_or_pow_and_keep_their_values(tmp_path):
    path = export(_Powers(), tmp_path / "powers.onnx", example=torch.rand(1, 3, 4, 4))
    counts = ops(path)
    assert counts["Where"] == 0 and counts["Pow"] == 1  # a whole power but 0 to 3 keeps its Pow (x ** 4), others exp(e log x)
    row = torch.tensor([-2.0, -0.5, 0.0, 1e-30, 0.18, 1.0, 3.0, 60.0, 1e4, 65504.0, float("inf"), float("nan")])
    image = row.reshape(1, 1, 1, -1).expand(1, 3, 2, -1).contiguous()
    output = session(path).run(None, {"image": image.numpy()})[0]
    expected = _Powers()(image.double()).numpy()
    np.testing.assert_allclose(output, expected, rtol=5e-6, atol=1e-30, equal_nan=True)  # exp(e log x): a few ulps
    np.testing.assert_array_equal(output[:, 24:27], 1.0)  # x ** 0 is 1 at NaN and infinity too


GRADES = {
    "cinematic": CINEMATIC["grade"],
    "every control at its top": {"aces": True, "post_exposure": 20, "temperature": 100, "contrast": 100, "saturation": 100,
                                 "split_shadows": (0.0, 1.0, 0.5), "split_highlights": (1.0, 0.0, 0.3), "split_balance": 100},
    "every control at its bottom": {"aces": True, "post_exposure": -20, "temperature": -100, "contrast": -100, "saturation": -100,
                                    "split_shadows": (1.0, 0.0, 0.7), "split_highlights": (0.0, 1.0, 0.2), "split_balance": -100},
    "ACEScct": {"aces": True, "log_space": "acescct", "contrast": 40, "saturation": -30, "split_shadows": (0.3, 0.5, 0.6),
                "split_highlights": (0.5, 0.7, 0.4)},
    "linear, split toning": {"contrast": -30, "saturation": -40, "split_balance": 20, "split_shadows": (0.2, 0.9, 0.5),
                             "split_highlights": (0.5, 0.1, 0.7)},
}
EDGES = (0.0, -0.0, 1e-45, 1e-38, 2.0**-17, 2.0**-16, 2.0**-15, 2.0**-14, 0.18, 1.0, 60.0, 65504.0, 1e6, 3e38,
         -1e-30, -2.0**-16, -1.0, -60.0, -65504.0, -3e38, float("inf"), -float("inf"), float("nan"))
"""Zeros, denormals, ACEScc's cut points, half-float's top and beyond, out-of-gamut negatives, infinities and NaN."""


def extreme_frame() -> torch.Tensor:
    """Each edge value against every other in the three channels, over the demo scene's rows."""
    edges = torch.tensor(EDGES)
    rows = torch.stack([torch.stack((edges, edges.roll(k), edges.roll(2 * k))) for k in range(1, 8)], dim=1)
    return torch.cat((rows.unsqueeze(0), tg.scene.demo_scene(9, len(EDGES))), dim=2)


def pixel_error(output: np.ndarray, expected: torch.Tensor) -> float:
    """The largest error in units of its pixel's largest channel (at least 1): the scale float32 colour matrices round
    at, where an output channel cancels to near 0 from channels of 1e4."""
    expected = expected.double().numpy()
    assert not np.isnan(output).any() and not np.isnan(expected).any()
    return float((np.abs(output - expected) / np.maximum(1.0, np.abs(expected).max(axis=1, keepdims=True))).max())


@pytest.mark.parametrize("name", GRADES)
def test_grade_exports_with_one_where_and_matches_pytorch_at_the_extremes(tmp_path, name):
    """The grade's strip body keeps one ``Where``, the non-finite policy's: ACEScc, split toning and luminance export
    with clamps and per-channel factors instead of comparisons, ``Where`` and ``ReduceSum``."""
    look = tg.PostFX.from_config({"grade": GRADES[name]}).eval()
    path = export(look, tmp_path / "grade.onnx")
    counts = ops(path)
    assert counts["Where"] == 1 and counts["IsNaN"] == 1 and counts["ReduceSum"] == 0, counts
    assert not {"Less", "LessOrEqual", "Greater", "GreaterOrEqual", "Equal", "Sign", "Pow"} & set(counts), counts
    image = extreme_frame()
    with torch.no_grad():
        expected = look(image)
    for runtime, precision in (("onnxruntime", None), ("openvino", "f32")):
        runner = session(path, runtime, precision)
        assert pixel_error(runner.run(None, {"image": image.numpy()})[0], expected) <= TOLERANCE, runtime


def test_split_toning_inputs_blend_per_sample_without_where(tmp_path):
    """Graph-input tints of either sign pick their soft-light branch by a 0/1 factor from their sign; PyTorch's reference
    picks it by ``Where`` on the blend, per pixel. Balance ±100 puts one blend of each pixel at 0.5, the branches' meeting
    point. OpenVINO takes the inputs' defaults only (it reads them as constants): the exported look's."""
    look = tg.PostFX(grade={"aces": True, "contrast": 20, "split_shadows": (0.0, 1.0, 0.5), "split_highlights": (1.0, 0.0, 0.3),
                            "split_balance": 100})
    path = export(look, tmp_path / "inputs.onnx", grade_inputs=True)
    assert ops(path)["GreaterOrEqual"] == 0  # soft light's per-pixel test of the blend; the tints' signs are Greater
    per_sample = tg.ColorGrade(aces=True, contrast=20, split_shadows=torch.tensor([[0.0, 1.0, 0.5], [0.8, 0.3, 0.5], [0.4, 0.5, 0.6]]),
                               split_highlights=torch.tensor([[1.0, 0.0, 0.3], [0.2, 0.5, 0.9], [0.6, 0.5, 0.4]]),
                               split_balance=torch.tensor([100.0, -100.0, 10.0]))
    runs = {"onnxruntime": (extreme_frame().expand(3, -1, -1, -1).contiguous(), tg.onnx.grade_feeds(per_sample, 3)),
            "openvino": (extreme_frame(), tg.onnx.grade_feeds(look.grade, 1))}
    for runtime, (image, controls) in runs.items():
        runner = session(path, runtime, "f32" if runtime == "openvino" else None)
        fed = {name: value.numpy() for name, value in controls.items()} if runtime == "onnxruntime" else {}
        with torch.no_grad():
            expected = tg.onnx.graph.GradeWithInputs(aces=True)(image, *controls.values())
        assert pixel_error(runner.run(None, {"image": image.numpy(), **fed})[0], expected) <= TOLERANCE, runtime


class _LogEncodings(torch.nn.Module):
    """ACEScc's encode, decode and contrast (one pivot-folded power), and ACEScct's encode and decode, as the grade exports them."""

    def forward(self, x):
        from torchgrade.color import aces_to_acescc, acescc_to_aces, acescct_to_linear, linear_to_acescct
        from torchgrade.grading.steps import log_contrast

        return torch.cat([aces_to_acescc(x), acescc_to_aces(x * 1.5 - 0.5), log_contrast(x, 60.0, "acescc"), log_contrast(x, -60.0, "acescc"),
                          linear_to_acescct(x), acescct_to_linear(x)], dim=1)


def test_log_encodings_export_without_where_and_keep_their_values_at_the_cut_points(tmp_path):
    path = export(_LogEncodings(), tmp_path / "log.onnx", example=torch.rand(1, 3, 4, 4))
    assert ops(path)["Where"] == 0 and not {"Less", "LessOrEqual"} & set(ops(path))
    codes = [(math.log2(v) + 9.72) / 17.52 for v in (2.0**-16, 2.0**-15)]
    row = torch.tensor([-1.0, 0.0, 1e-45, 2.0**-17, 2.0**-16, 2.0**-15, 2.0**-15 * (1 + 2.0**-23), 2.0**-7, 0.18, 1.0, 65504.0, 1e6,
                        *codes, (codes[1] + 0.5) / 1.5, (9.72 - 15.0) / 17.52, tg.color.ACESCCT_CUT_LOG, 1.5])
    image = row.reshape(1, 1, 1, -1).expand(1, 3, 1, -1).contiguous()
    with torch.no_grad():
        expected = _LogEncodings()(image).double().numpy()
    output = session(path).run(None, {"image": image.numpy()})[0]
    np.testing.assert_allclose(output, expected, rtol=2e-6, atol=1e-9)
_EXTREMES = (0.0, -0.0, 1e-45, 1e-40, 1e-30, 1e-8, 1e-4, 0.18, 1.0, 60.0, 61.0, 65504.0, 1e30, math.nan, math.inf, -math.inf,
             -1e-40, -1.0, -65504.0)


def _rrt_edges() -> torch.Tensor:
    """Pixels (N, 3) at the RRT's edges: hues a float step either side of red (0°/360°) and of cyan (the ±180° wrap),
    near-neutrals, and colours scaled to put the AP0 ``yc`` on the glow's ends 2/3·0.08 and 2·0.08 and a step away."""
    pixels = []
    for level in (1e-4, 0.01, 0.18, 1.0, 10.0, 60.0):
        for spread in (0.0, 1e-7, -1e-7, 1e-5, -1e-3, 0.05, -0.05):
            for red in (1.5, 0.5, 1.0 + 1e-6, 1.0 - 1e-6, 1.0):
                pixels.append([level * red, level * (1.0 + spread), level * (1.0 - spread)])
    colours = torch.rand(40, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64) ** 2
    yc = _yc(*unity_to_aces(colours.T[:, :, None]).split(1)).flatten()
    for end in (2.0 / 3.0 * 0.08, 2.0 * 0.08):
        for step in (1.0 - 1e-6, 1.0, 1.0 + 1e-6):
            pixels += (colours * (end * step / yc)[:, None]).tolist()
    return torch.tensor(pixels)


def _aces_frame() -> torch.Tensor:
    """Every pair of :data:`_EXTREMES` in two channels (the third cycling through them), :func:`_rrt_edges`, and
    random colours all round the hue circle over ten decades and out of gamut, as one (1, 3, H, 64) frame."""
    generator = torch.Generator().manual_seed(1)
    edges = torch.tensor(_EXTREMES)
    pairs = torch.cartesian_prod(edges, edges)
    extremes = torch.cat((pairs, edges.repeat(len(edges))[:, None]), dim=1)
    hue = torch.rand(2000, 1, generator=generator) * 2.0 * math.pi
    circle = torch.cat((hue, hue - 2.0 * math.pi / 3.0, hue + 2.0 * math.pi / 3.0), dim=1).cos()
    level = 10.0 ** (torch.rand(2000, 1, generator=generator) * 10.0 - 6.0)
    chroma = torch.rand(2000, 1, generator=generator)
    pixels = torch.cat((extremes, _rrt_edges(), level * (1.0 + chroma * circle), torch.randn(500, 3, generator=generator) * 3.0))
    pixels = torch.cat((pixels, torch.zeros(-len(pixels) % 64, 3)))
    return pixels.T.reshape(1, 3, -1, 64).contiguous()


@pytest.mark.parametrize("mode, selects, comparisons", [("aces", 1, 0), ("unreal_filmic", 4, 2)])
def test_aces_rrt_exports_without_selects_and_matches_pytorch_at_extremes(tmp_path, mode, selects, comparisons):
    """The ACES fit and Unreal's filmic curve, which share the RRT glow and red modifier: no Where but the non-finite
    policy's NaN → 0 (and Unreal's toe, shoulder and blend: three, two on comparisons), no Pow, Sign or channel reductions;
    PyTorch's values at 0, denormals, 60, 65504, 1e30, ±Inf, NaN, negatives, both hue wraps, near-neutrals and the
    glow's ends."""
    look = tg.PostFX(tonemap=mode).eval()
    path = export(look, tmp_path / f"{mode}.onnx")
    counts = ops(path)
    assert counts["Where"] == selects and counts["IsNaN"] == 1
    assert sum(counts[op] for op in ("Less", "Greater", "Equal", "LessOrEqual", "GreaterOrEqual")) == comparisons
    assert not {"Pow", "Sign", "ReduceMax", "ReduceMin"} & set(counts)
    image = _aces_frame()
    for runtime, precision in (("onnxruntime", None), ("openvino", "f32")):
        assert verify(look, path, image, runtime, precision) <= TOLERANCE, runtime


@pytest.mark.parametrize("weight", [smoothstep_hue_weight, cubic_basis_hue_weight])
def test_red_hue_distance_weighs_as_the_centred_hue(weight):
    """The hue's distance from red gives the red modifier's weights of the CTL's centred hue (``atan2`` in float64, 0
    for neutrals) on both sides of red, past ±90° (where it stops at 90°), at the ±180° wrap (g = b above r), for
    neutrals (0°) and greys a float step off neutral."""
    rgb = torch.tensor([[1.0, 0.5, 0.5], [0.0, 1.0, 1.0], [0.2, 0.7, 0.7], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.9, 0.2],
                        [1.0, 0.2, 0.9], [0.3, 1.0, 0.0], [0.5, 0.5 + 2**-24, 0.5], [0.5, 0.5, 0.5 + 2**-24], [0.5 + 2**-24, 0.5, 0.5],
                        [1.0, 1e-6, 0.0], [1.0, 0.0, 1e-6], [0.0, 1.0, 1.0 - 1e-6], [0.0, 1.0 - 1e-6, 1.0]]).T[:, :, None]
    r, g, b = rgb.double().squeeze(-1).numpy()
    centred = torch.from_numpy(np.degrees(np.arctan2(np.sqrt(3.0) * (g - b), 2.0 * r - g - b))).reshape(1, -1, 1)
    torch.testing.assert_close(weight(_red_hue_distance(*rgb.split(1))), weight(centred).float(), rtol=0.0, atol=1e-6)
