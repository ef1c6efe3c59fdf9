"""The operator ``torchgrade::lut_lookup``: torch.library's own checks (schema, fake kernel, autograd registration,
AOT dispatch), its gradients against finite differences in float64, ``torch.compile(fullgraph=True)`` of a LUT with
the operator in the graph, its ONNX export as the torch form's standard operations (checked with onnxruntime), its C
loop bound to torch's own OpenMP runtime and loaded from the package, and its torch form's one warning where the
package was built without it."""

import warnings
from pathlib import Path

import numpy as np
import onnxruntime
import pytest
import torch

import torchgrade
from torchgrade.lut import LUT3D, identity_table, operator
from torchgrade.lut.apply import lookup
from torchgrade.lut.lattice import planar_table
from torchgrade.lut.operator import lut_lookup, torch_form
from torchgrade.onnx import export

INTERPOLATIONS = ["tetrahedral", "trilinear"]


def inputs(dtype=torch.float64, requires_grad=False):
    """Codes off the lattice planes and tetrahedron boundaries (where the lookup has kinks), a table, a per-channel
    domain."""
    generator = torch.Generator().manual_seed(3)
    codes = torch.rand(3, 24, generator=generator, dtype=dtype) * 1.1 - 0.05
    table = torch.rand(5, 5, 5, 3, generator=generator, dtype=dtype) * 2 - 0.5
    low, high = torch.tensor([0.0, -0.1, 0.05]), torch.tensor([1.0, 1.2, 0.9])
    return codes.requires_grad_(requires_grad), table.requires_grad_(requires_grad), low, high


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_torch_librarys_checks_pass(interpolation):
    codes, table, low, high = inputs(requires_grad=True)
    results = torch.library.opcheck(lut_lookup, (codes, table, low, high, interpolation))
    assert set(results.values()) == {"SUCCESS"}


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
@pytest.mark.parametrize("nan_free", [False, True])
def test_gradients_for_the_image_and_the_table_match_finite_differences(interpolation, nan_free):
    codes, table, low, high = inputs(requires_grad=True)
    assert torch.autograd.gradcheck(lambda x, t: lut_lookup(x, t, low, high, interpolation, nan_free), (codes, table))


def test_a_learnable_lut_with_a_shaper_has_the_torch_forms_gradients():
    lut = LUT3D(torch.rand(9, 9, 9, 3) * 2 - 0.5, shaper="logc", learnable=True)
    image = (torch.rand(1, 3, 6, 5) * 4).requires_grad_()
    lut(image).square().sum().backward()
    got = image.grad.clone(), lut.table.grad.clone()
    image.grad, lut.table.grad = None, None
    lookup(image, planar_table(lut.table), 9, lut.shaper, lut.domain_min, lut.domain_max, "tetrahedral", None, None,
           lut.curve_range, "linear").square().sum().backward()
    torch.testing.assert_close(got[0], image.grad, atol=1e-4, rtol=1e-4)
    torch.testing.assert_close(got[1], lut.table.grad, atol=1e-4, rtol=1e-4)


def graph_operators(function, *args) -> list:
    """The operators of the graphs ``torch.compile(fullgraph=True)`` hands its backend for ``function(*args)``."""
    seen = []

    def backend(graph_module, example_inputs):
        seen.extend(node.target for node in graph_module.graph.nodes if node.op == "call_function")
        return graph_module.forward

    torch.compile(function, backend=backend, fullgraph=True)(*args)
    return seen


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_torch_compile_fullgraph_takes_a_lut_lookup_with_the_operator_in_its_graph(interpolation):
    lut = LUT3D(torch.rand(9, 9, 9, 3), shaper="logc", output_encoding="srgb")
    image = torch.rand(1, 3, 16, 20) * 2
    assert torch.ops.torchgrade.lut_lookup.default in graph_operators(lambda x: lut(x, interpolation), image)
    compiled = torch.compile(lambda x: lut(x, interpolation), fullgraph=True)
    torch.testing.assert_close(compiled(image), lut(image, interpolation), atol=1e-6, rtol=0)


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_an_onnx_export_of_a_lut_holds_the_torch_forms_standard_operations(interpolation, tmp_path):
    """The TorchScript exporter records the operator as its torch form (its Tracer kernel): no custom node, the
    gathers of the "gather" backend, and onnxruntime gives the operator's values."""
    import onnx

    lut = LUT3D(torch.rand(9, 9, 9, 3), shaper="logc", interpolation=interpolation)
    image = torch.rand(1, 3, 8, 10) * 2
    path = export(lut, tmp_path / "lut.onnx", example=image, lut_backend="gather", strips=False)
    model = onnx.load(str(path))
    assert {node.domain for node in model.graph.node} <= {"", "ai.onnx"}
    assert "Gather" in {node.op_type for node in model.graph.node}
    got = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"]).run(None, {model.graph.input[0].name: image.numpy()})[0]
    np.testing.assert_allclose(got, lut(image).numpy(), atol=2e-6, rtol=0)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_c_loop_gives_the_torch_forms_values(dtype):
    codes, table, low, high = inputs(dtype)
    specials = torch.tensor([float("nan"), float("inf"), -float("inf"), 1e30, -1e30, 7e4, -0.0], dtype=dtype)
    codes = torch.cat([codes, specials.expand(3, -1), specials.roll(1).expand(3, -1)], -1)
    for interpolation in INTERPOLATIONS:
        # one rounding of a coordinate (a product in C, a division in torch) times the table's steps (below 2)
        atol = 8 * torch.finfo(dtype).eps * 2 + torch.finfo(dtype).eps * 4 * 2
        torch.testing.assert_close(lut_lookup(codes, table, low, high, interpolation), torch_form(codes, table, low, high, interpolation),
                                   atol=atol, rtol=0)


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="platform-conditional: reads Linux's /proc/self/maps")
def test_the_c_loop_is_the_packages_and_runs_on_torchs_own_openmp_runtime():
    assert operator.NATIVE is not None, "torchgrade.lut._lookup was not built: see setup.py"
    assert Path(operator.NATIVE.__file__).parent == Path(torchgrade.__file__).parent / "lut"
    LUT3D(identity_table(5))(torch.rand(1, 3, 64, 64))
    runtimes = {line.split()[-1] for line in Path("/proc/self/maps").read_text().splitlines() if "libgomp" in line}
    assert len(runtimes) <= 1 and all(Path(torch.__file__).parent in Path(path).parents for path in runtimes)


def test_without_the_c_loop_the_torch_form_runs_with_one_warning(monkeypatch):
    monkeypatch.setattr(operator, "NATIVE", None)
    operator._warn_once.cache_clear()
    codes, table, low, high = inputs()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = lut_lookup(codes, table, low, high, "tetrahedral")
        second = lut_lookup(codes, table, low, high, "trilinear")
    assert [w.category for w in caught] == [RuntimeWarning] and "without its compiled LUT loop" in str(caught[0].message)
    assert torch.equal(first, torch_form(codes, table, low, high, "tetrahedral"))
    assert torch.equal(second, torch_form(codes, table, low, high, "trilinear"))


@pytest.mark.parametrize("change, message", [
    (lambda a: {**a, "codes": a["codes"].reshape(1, 3, -1)}, "codes \\(3, P\\)"),
    (lambda a: {**a, "codes": a["codes"][:2]}, "codes \\(3, P\\)"),
    (lambda a: {**a, "table": a["table"][:, :4]}, "table \\(S, S, S, 3\\)"),
    (lambda a: {**a, "table": a["table"].float()}, "one floating-point dtype"),
    (lambda a: {**a, "low": a["low"][:2]}, "two \\(3,\\) tensors"),
    (lambda a: {**a, "interpolation": "cubic"}, "interpolation must be one of"),
])
def test_arguments_the_c_loop_would_misread_are_refused(change, message):
    codes, table, low, high = inputs()
    arguments = change({"codes": codes, "table": table, "low": low, "high": high, "interpolation": "tetrahedral"})
    with pytest.raises(ValueError, match=message):
        lut_lookup(arguments["codes"], arguments["table"], arguments["low"], arguments["high"], arguments["interpolation"])
