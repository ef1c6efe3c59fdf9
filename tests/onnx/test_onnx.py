"""ONNX export: onnxruntime against PyTorch at two batch sizes and two resolutions (one odd) from one file,
identity stages adding no nodes, grading controls as graph inputs, opsets of the LUT backends."""

import collections

import numpy as np
import onnx
import pytest
import torch

import torchgrade as tg
from torchgrade.base.images import sanitize
from torchgrade.onnx import export, grade_feeds, node_count, session, verify
from torchgrade.onnx.verify import graph_nodes

from reference.onnx import display_error, hdr, SHAPES, STEP_TOLERANCE, TOLERANCE

FULL_GRADE = dict(
    post_exposure=0.5, temperature=20, tint=5, contrast=30, color_filter=(1.0, 0.9, 0.8), hue_shift=10, saturation=20,
    split_shadows=(0.4, 0.5, 0.6), split_highlights=(0.6, 0.5, 0.4), split_balance=10,
    channel_mixer=((1.1, 0.0, 0.0), (0.0, 0.9, 0.1), (0.0, 0.0, 1.0)),
    shadows=(1.0, 0.9, 1.0), midtones=(1.0, 1.0, 1.1), highlights=(0.9, 1.0, 1.0),
)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """Export a module once per (name, options) and reuse the file for every shape."""
    folder = tmp_path_factory.mktemp("onnx")
    cache = {}

    def get(name, module, **options):
        if name not in cache:
            cache[name] = export(module, folder / f"{name}.onnx", **options)
        return cache[name]

    return get


@pytest.mark.parametrize("mode", tg.TONEMAP_MODES)
def test_every_tonemapper_matches(exported, mode):
    module = tg.ToneMap(mode)
    path = exported(f"tonemap_{mode}", module)
    for shape in SHAPES:
        assert verify(module, path, hdr(shape)) <= TOLERANCE


@pytest.mark.parametrize("aces", [False, True])
def test_full_grade_matches(exported, aces):
    module = tg.ColorGrade(aces=aces, **FULL_GRADE)
    path = exported(f"grade_{aces}", module)
    for shape in SHAPES:
        assert display_error(module, path, hdr(shape)) <= TOLERANCE


@pytest.mark.parametrize("mode", tg.bloom.BLOOM_MODES)
@pytest.mark.parametrize("bicubic", [False, True])
def test_bloom_matches(exported, mode, bicubic):
    # Three levels: every test size has at least that many, so PyTorch and the fixed-depth graph agree.
    module = tg.Bloom(mode=mode, intensity=0.8, max_iterations=3, bicubic_upsampling=bicubic)
    path = exported(f"bloom_{mode}_{bicubic}", module)
    for shape in SHAPES:
        assert display_error(module, path, hdr(shape)) <= TOLERANCE


def test_one_bloom_graph_serves_frames_of_every_pyramid_depth(exported):
    """PyTorch's depth follows the frame (9x9: 1 level ... 300x420: 6); the graph masks levels at run time."""
    module = tg.Bloom(mode="scattering", intensity=0.9, scatter=0.6)
    path = exported("bloom_every_depth", module)
    sizes = [(9, 9), (16, 24), (37, 53), (64, 96), (133, 201), (300, 420)]
    assert len({tg.bloom.pyramid_depth(h, w, 16, 2) for h, w in sizes}) == 6
    for height, width in sizes:
        assert display_error(module, path, hdr((1, 3, height, width))) <= TOLERANCE, (height, width)


LUT_LOOK = torch.nn.Sequential(tg.ColorGrade(contrast=20, saturation=15), tg.ToneMap("neutral"))
LUTS = {encoding: tg.bake_lut(LUT_LOOK, size=17, output_encoding=encoding) for encoding in tg.lut.OUTPUT_ENCODINGS}
LUT = LUTS["linear"]


@pytest.mark.parametrize("encoding", tg.lut.OUTPUT_ENCODINGS)
@pytest.mark.parametrize("interpolation", ["trilinear", "tetrahedral"])
@pytest.mark.parametrize("backend, opset", [("slices", 17), ("gather", 17), ("volume", 20)])
def test_lut_matches_in_both_interpolations_and_encodings(exported, interpolation, backend, opset, encoding):
    module = tg.PostFX(lut=LUTS[encoding], interpolation=interpolation)
    path = exported(f"lut_{interpolation}_{backend}_{encoding}", module, lut_backend=backend)
    model = onnx.load(str(path))
    assert model.opset_import[0].version == opset
    ops = collections.Counter(node.op_type for node in graph_nodes(model.graph))
    uses_grid = interpolation == "trilinear" and backend != "gather"
    assert (ops["GridSample"] > 0) == uses_grid and (ops["Gather"] > 0 or uses_grid)
    for shape in SHAPES:
        assert verify(module, path, hdr(shape)) <= TOLERANCE


def test_strip_lookup_matches_the_gather_kernel_on_lattice_points():
    """Lattice points come back exactly from the slices layout (no half-texel offset)."""
    from torchgrade.lut.kernels import strip_table, trilinear_strip

    table = torch.rand(5, 5, 5, 3)
    unit = tg.lut.lattice(5).permute(3, 0, 1, 2).reshape(1, 3, 25, 5).float()
    looked_up = trilinear_strip(unit, strip_table(table))
    torch.testing.assert_close(looked_up, table.reshape(1, 25, 5, 3).permute(0, 3, 1, 2), atol=1e-6, rtol=0)


FULL_LOOK = dict(
    exposure={"speed": 1.5},
    bloom={"intensity": 0.5, "max_iterations": 3},
    grade={"aces": True, "contrast": 20, "saturation": 10, "temperature": 10},
    tonemap="aces",
)


def test_full_look_matches_including_the_adaptation_state(exported):
    look = tg.PostFX(**FULL_LOOK)
    path = exported("full_look", look)
    names = [i.name for i in session(path).get_inputs()]
    assert names == ["image", "adapted", "dt"]
    for shape in SHAPES:
        adapted = torch.linspace(0.0, 2.0, shape[0])  # the first sample starts a sequence
        assert verify(look, path, (hdr(shape), adapted, torch.tensor(0.2))) <= TOLERANCE


def test_identity_grade_and_zero_bloom_add_no_nodes(exported):
    plain = node_count(exported("tonemap_only", tg.PostFX(tonemap="neutral")))
    with_identity = tg.PostFX(grade=tg.ColorGrade(), bloom=tg.Bloom(intensity=0.0), tonemap="neutral")
    sequential = torch.nn.Sequential(tg.ColorGrade(), tg.Bloom(intensity=0.0), tg.ToneMap("neutral"))
    assert node_count(exported("identity_look", with_identity)) == plain
    assert node_count(exported("identity_sequential", sequential)) == node_count(exported("tonemap_neutral", tg.ToneMap("neutral")))
    graded = tg.PostFX(grade={"contrast": 10}, tonemap="neutral")
    assert node_count(exported("graded_look", graded)) > plain


def test_grading_controls_as_inputs_serve_many_looks(exported):
    baked_look = tg.PostFX(grade=FULL_GRADE, tonemap="neutral")
    inputs_path = exported("grade_inputs", baked_look, grade_inputs=True)
    baked_path = exported("grade_baked", baked_look)
    runner, baked_runner = session(inputs_path), session(baked_path)
    assert [i.name for i in onnx.load(str(inputs_path)).graph.input] == ["image"] + list(tg.onnx.GRADE_INPUTS)
    other_look = tg.PostFX(grade={"contrast": -30, "hue_shift": -40, "split_balance": -20}, tonemap="neutral")
    for shape in SHAPES:
        image = hdr(shape)
        feeds = {"image": image.numpy(), **{k: v.numpy() for k, v in grade_feeds(baked_look.grade, shape[0]).items()}}
        from_inputs, baked = runner.run(None, feeds)[0], baked_runner.run(None, {"image": image.numpy()})[0]
        np.testing.assert_allclose(from_inputs, baked, atol=3 * TOLERANCE, rtol=0)
        # the two graphs round apart in float32 (the baked one folds its matrices in float64): each as near the float64
        # look as the other, and as eager float32 is
        with torch.no_grad():
            exact = tg.PostFX(grade=FULL_GRADE, tonemap="neutral").double()(image.double()).numpy()
            eager = baked_look(image).numpy()
        assert np.abs(from_inputs - exact).max() <= max(np.abs(baked - exact).max(), np.abs(eager - exact).max()) + 1e-5
        feeds.update({k: v.numpy() for k, v in grade_feeds(other_look.grade, shape[0]).items()})
        with torch.no_grad():
            np.testing.assert_allclose(runner.run(None, feeds)[0], other_look(image).numpy(), atol=STEP_TOLERANCE, rtol=0)


def test_grading_controls_as_inputs_per_sample(exported):
    """One batch, a different look per sample."""
    look = tg.PostFX(grade={"contrast": 10}, tonemap="neutral")
    runner = session(exported("grade_inputs_small", look, grade_inputs=True))
    image = hdr((2, 3, 9, 11))
    contrasts = torch.tensor([-40.0, 60.0])
    feeds = {k: v.numpy() for k, v in grade_feeds(tg.ColorGrade(contrast=contrasts), 2).items()}
    output = runner.run(None, {"image": image.numpy(), **feeds})[0]
    for sample, contrast in enumerate(contrasts.tolist()):
        expected = tg.PostFX(grade={"contrast": contrast}, tonemap="neutral")(image[sample : sample + 1])
        np.testing.assert_allclose(output[sample : sample + 1], expected.detach().numpy(), atol=STEP_TOLERANCE, rtol=0)


def test_bad_options_raise(tmp_path):
    with pytest.raises(ValueError, match="lut_backend"):
        export(tg.ToneMap(), tmp_path / "x.onnx", lut_backend="texture")
    with pytest.raises(ValueError, match="lut_backend must be one of 'slices'"):
        tg.LUT3D(tg.lut.identity_table(3)).export_form("trilinear", "strip")
    with pytest.raises(ValueError, match="opset >= 20"):
        export(tg.PostFX(lut=LUT), tmp_path / "x.onnx", lut_backend="volume", opset=17)
    with pytest.raises(ValueError, match="needs a ColorGrade"):
        export(tg.ToneMap(), tmp_path / "x.onnx", grade_inputs=True)


class _NonFinite(torch.nn.Module):
    """The non-finite policy, and ``nan_to_num`` with replacements of its own for the infinities."""

    def forward(self, image):
        return sanitize(image) + torch.nan_to_num(image, nan=1.0, posinf=5.0, neginf=-7.0)


def test_nan_to_num_exports_without_float64_and_matches_pytorch(tmp_path):
    path = export(_NonFinite(), tmp_path / "non_finite.onnx", example=torch.rand(1, 3, 4, 4))
    row = torch.tensor([float("nan"), float("inf"), -float("inf"), 1.0, 7e4, -3e38])
    image = row.reshape(1, 1, 1, 6).expand(2, 3, 5, 6).contiguous()
    runner = session(path)
    output = runner.run(None, {"image": image.numpy()})[0]
    # sanitize: 0, 65504, -65504, 1, 65504, -65504; nan_to_num: 1, 5, -7, 1, 7e4, -3e38
    expected = torch.tensor([1.0, 65509.0, -65511.0, 2.0, 65504.0 + 7e4, -65504.0 - 3e38])
    assert np.array_equal(output[0, 0, 0], expected.numpy())
    assert np.array_equal(output, _NonFinite()(image).numpy())
    casts = [node for node in graph_nodes(onnx.load(str(path)).graph) if node.op_type == "Cast"]
    assert all(attribute.i != onnx.TensorProto.DOUBLE for node in casts for attribute in node.attribute)


def test_the_stage_after_exposure_scrubs_no_nan_again_and_non_finite_frames_still_match(exported):
    """The exposed frame holds no NaN, so bloom after it bounds its input without a second NaN pass."""
    look = tg.PostFX(exposure={"speed": 1.5}, bloom={"mode": "scattering", "intensity": 0.6})
    path = exported("exposure_bloom", look)
    nodes = graph_nodes(onnx.load(str(path)).graph)
    isnan_outputs = {node.output[0] for node in nodes if node.op_type == "IsNaN"}
    scrubs = [node for node in nodes if node.op_type == "Where" and node.input[0] in isnan_outputs]
    assert len(scrubs) == 1  # the input's
    image = hdr((1, 3, 37, 53))
    image[0, :, 3, 4:8] = torch.tensor([float("nan"), float("inf"), -float("inf"), 1e30]).expand(3, 4)
    inputs = (image, torch.tensor([0.4]), torch.tensor(0.2))
    with torch.no_grad():
        peak = float(look.frame(*inputs)[0].abs().max())
    for runtime in ("onnxruntime", "openvino"):
        assert verify(look, path, inputs, runtime, "f32") / peak <= TOLERANCE, runtime


def test_sessions_on_a_given_number_of_threads_match(exported):
    module = tg.ToneMap("aces")
    path = exported("tonemap_threads", module)
    image = hdr((1, 3, 16, 24))
    with torch.no_grad():
        expected = module(image).numpy()
    for runtime in ("onnxruntime", "openvino"):
        one = session(path, runtime, "f32" if runtime == "openvino" else None, threads=1)
        if runtime == "onnxruntime":
            assert one.get_session_options().intra_op_num_threads == 1
        assert float(np.abs(one.run(None, {"image": image.numpy()})[0] - expected).max()) <= TOLERANCE
    for threads in (0, -2, 1.5, True):
        with pytest.raises(ValueError, match="threads"):
            session(path, threads=threads)


@pytest.mark.parametrize("failing", ["scan_strips", "fold_constants", "describe"])
def test_a_failed_export_leaves_the_previous_file_whole_and_no_temporary(tmp_path, monkeypatch, failing):
    """A full disk (or any failure) in any step of an export: the file a previous export wrote is untouched, as the
    steps write a temporary file beside it that replaces it only once whole and checked."""
    import errno

    import torchgrade.onnx.exporter as exporter

    path = tmp_path / "look.onnx"
    tg.onnx.export(tg.ToneMap("aces"), path)
    before = path.read_bytes()
    step = getattr(exporter, failing)

    def full_disk(*args, **kwargs):
        step(*args, **kwargs)  # the step runs, rewriting the temporary file, then the disk fills
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(exporter, failing, full_disk)
    with pytest.raises(OSError, match="No space left"):
        tg.onnx.export(tg.PostFX(grade={"contrast": 20}, tonemap="aces"), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["look.onnx"]
    onnx.checker.check_model(str(path))
