"""ONNX export of torchgrade modules and looks, and verification with onnxruntime.

``export(module, path)`` writes one ONNX file that serves every batch size and resolution: the
image input ``"image"`` ``(batch, 3, height, width)`` and the output ``"output"`` have dynamic axes.

**Exporter and opset.** torchgrade uses PyTorch's TorchScript-based exporter
(``torch.onnx.export(..., dynamo=False)``) at **opset 17** by default. Opset 17 keeps every model
within the operators that OpenVINO and TensorRT accept (the "Deployment portability" rule of the
design), and the exporter turns a look into a graph in about a second, where the dynamo exporter
takes minutes for the bloom pyramid's symbolic shapes and cannot lower to opset 17 (its
down-conversion writes opset-18 ``Split`` attributes into opset-17 files). Where PyTorch's
symbolic functions are missing or wrong for an op torchgrade uses, :func:`_symbolics` supplies
them for the duration of the export: ``exp2``, ``expm1``, ``rad2deg``, ``frac``, Python's ``//`` on sizes (the stock
symbolic truncates), ``movedim`` with negative
dimensions, and ``avg_pool2d`` with ``divisor_override`` (bloom's 2x2 sums, which the stock
symbolic silently exports as means).

**LUTs.** ``lut_backend`` picks how a :class:`~torchgrade.lut.LUT3D` is looked up in the graph:

* ``"strip"`` (default, opset 17): trilinear lookups use the 2-D strip layout, the ``(S, S, S)``
  volume laid out as an ``S x S²`` image sampled by two 4-D ``GridSample`` nodes and a lerp;
  tetrahedral lookups use gathers (no GridSample form exists for them);
* ``"gather"`` (opset 17): both interpolations as ``Gather`` nodes, exactly PyTorch's kernels;
* ``"volume"`` (opset 20): trilinear with one 5-D ``GridSample`` (mode ``"linear"``), which
  onnxruntime runs from 1.17 but OpenVINO rejects and TensorRT has mis-mapped; tetrahedral stays
  on gathers.

**Bloom.** In PyTorch the pyramid depth of :class:`~torchgrade.Bloom` follows the frame size
through Python integers, which tracing would freeze. The graph instead holds every level a frame
of up to :data:`~torchgrade.bloom.MAX_FRAME_SIDE` pixels a side can have and masks out, from the runtime shape, the
levels the frame at hand does not have (``bloom(..., fixed_depth=...)``), so one graph matches
PyTorch at every resolution up to that size.

**Exposure.** A model with an :class:`~torchgrade.AutoExposure` stage is stateless: it takes
``"image"``, ``"adapted"`` ``(batch,)`` (the previous frame's adapted luminance; ``<= 0`` starts
a sequence) and ``"dt"`` (seconds, a scalar), and returns ``"output"`` and ``"adapted"``
(named ``"adapted_out"``) for the next frame.

**Grading controls as inputs.** With ``grade_inputs=True`` every :class:`~torchgrade.ColorGrade`
control becomes a graph input named as the control, per sample: scalars ``(batch,)``
(``post_exposure``, ``temperature``, ``tint``, ``contrast``, ``split_balance``,
``shadows_start``, ``shadows_end``, ``highlights_start``, ``highlights_end``, ``hue_shift``,
``saturation``), colours ``(batch, 3)`` (``color_filter``, ``split_shadows``,
``split_highlights``, ``shadows``, ``midtones``, ``highlights``), trackballs ``(batch, 4)``
(``lift``, ``gamma``, ``gain``) and ``channel_mixer`` ``(batch, 3, 3)``, in Unity's units. Every
grading step is then in the graph, so one model serves any look (and a different look per
sample); :func:`grade_feeds` gives a grade's values.
Only the ``aces`` switch and the curves (a variable number of control points) stay baked.
"""

from __future__ import annotations

import contextlib
import math
import statistics
import time
import warnings
from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np
import onnx as onnx_lib  # the onnx package (absolute import), not this module
import torch
from torch import nn

from .core import sanitize
from .exposure import AutoExposure
from .grade import CONTROLS, ColorGrade, color_grade
from .lut import LUT3D, lattice_unit, table_output, trilinear_grid_sample
from .pipeline import PostFX, exposure_frame

DEFAULT_OPSET = 17
"""Opset of every export unless a 5-D GridSample LUT asks for :data:`VOLUME_OPSET`."""
VOLUME_OPSET = 20
"""First opset with 5-D ``GridSample`` (mode spelled ``"linear"``)."""
LUT_BACKENDS = ("strip", "gather", "volume")
"""Frame (height, width) whose bloom pyramid depth an exported graph uses."""

Inputs = Union[torch.Tensor, Sequence[torch.Tensor]]


# ---------------------------------------------------------------- export-ready modules


def strip_table(table: torch.Tensor) -> torch.Tensor:
    """A ``(S, S, S, 3)`` table ``[b, g, r]`` as a ``(1, 3, S, S²)`` strip image: row ``g``, column ``b·S + r``."""
    size = table.shape[0]
    return table.permute(3, 1, 0, 2).reshape(1, 3, size, size * size)


def trilinear_strip(unit: torch.Tensor, strip: torch.Tensor) -> torch.Tensor:
    """Trilinear lookup of ``unit`` ``(N, 3, H, W)`` in [0, 1] with two 4-D ``grid_sample``s on a strip.

    Bilinear sampling at column ``b0·S + r``, row ``g`` interpolates red and green inside blue slice
    ``b0`` (red never crosses into the next slice: at ``r = S - 1`` its neighbour has weight 0);
    the two slices around ``b`` are then blended. ``align_corners=True`` puts -1 and +1 on the
    centres of the first and last texels, so lattice points are sampled exactly.
    """
    size = strip.shape[-2]
    n, _, height, width = unit.shape
    r, g, b = (unit * (size - 1)).unbind(1)
    low_slice = b.floor().clamp(max=size - 2)
    blend = (b - low_slice).unsqueeze(1)
    rows = g / (size - 1) * 2.0 - 1.0
    columns = (low_slice * size + r) / (size * size - 1) * 2.0 - 1.0
    step = 2.0 * size / (size * size - 1)

    def sample(x):
        grid = torch.stack((x, rows), dim=-1).reshape(1, n * height, width, 2)
        values = nn.functional.grid_sample(strip, grid, mode="bilinear", padding_mode="border", align_corners=True)
        return values.reshape(3, n, height, width).transpose(0, 1)

    low = sample(columns)
    return low + blend * (sample(columns + step) - low)


class LUTLookup(nn.Module):
    """A :class:`~torchgrade.lut.LUT3D` lookup with a fixed interpolation and graph form (``lut_backend``)."""

    def __init__(self, lut: LUT3D, interpolation: str, backend: str):
        super().__init__()
        self.lut = lut
        self.interpolation = interpolation
        self.grid = backend if interpolation == "trilinear" and backend != "gather" else None

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        if self.grid is None:
            return self.lut(image, self.interpolation)
        lut = self.lut
        x = sanitize(image)
        n, _, height, width = x.shape
        points = x.transpose(0, 1).reshape(3, -1)
        unit = lattice_unit(points, lut.shaper, lut.domain_min, lut.domain_max, lut.curve, lut.curve_range)
        unit = unit.reshape(3, n, height, width).transpose(0, 1)
        table = lut.table.to(x.dtype)
        if self.grid == "strip":
            y = trilinear_strip(unit, strip_table(table))
        else:
            y = trilinear_grid_sample(unit, table)
        return table_output(y, lut.output_encoding, lut.output_range)


class GradeWithInputs(nn.Module):
    """``ColorGrade`` whose controls are graph inputs: ``forward(image, *controls)`` in :data:`CONTROLS` order.

    Its curves (control points, not inputs) are baked into the graph.
    """

    def __init__(self, aces: bool, curves: Optional[dict] = None):
        super().__init__()
        self.aces = aces
        self.curves = curves or {}

    def forward(self, image: torch.Tensor, *controls: torch.Tensor) -> torch.Tensor:
        return color_grade(image, aces=self.aces, **dict(zip(CONTROLS, controls)), **self.curves)


class ExportGraph(nn.Module):
    """The stages of a look as one graph: ``(image[, adapted, dt][, *controls]) -> output[, adapted]``."""

    def __init__(self, stages: Sequence[nn.Module], exposure: Optional[AutoExposure] = None):
        super().__init__()
        self.stages = nn.ModuleList(stages)
        self.exposure = exposure

    def forward(self, image: torch.Tensor, *extra: torch.Tensor):
        if self.exposure is not None:
            adapted, dt, *controls = extra
            image, adapted = exposure_frame(self.exposure, image, adapted, dt)
        else:
            controls = list(extra)
        for stage in self.stages:
            image = stage(image, *controls) if isinstance(stage, GradeWithInputs) else stage(image)
        return (image, adapted) if self.exposure is not None else image


def _look_stages(module: nn.Module) -> tuple:
    """``(exposure or None, [(name, stage), ...])`` of any exportable module."""
    if isinstance(module, PostFX):
        stages = module.stages()
        exposure = stages.pop("exposure", None)
        if "lut" in stages:
            stages["lut"] = (stages["lut"], module.interpolation)
        return exposure, list(stages.items())
    if isinstance(module, AutoExposure):
        return module, []
    if isinstance(module, LUT3D):
        return None, [("lut", (module, "tetrahedral"))]
    return None, [("module", module)]


def export_graph(module: nn.Module, lut_backend: str = "strip", grade_inputs: bool = False) -> ExportGraph:
    """The export-ready form of ``module`` (see the module docstring for each stage's form)."""
    if lut_backend not in LUT_BACKENDS:
        raise ValueError(f"lut_backend must be one of {LUT_BACKENDS}, got {lut_backend!r}")
    exposure, named = _look_stages(module)
    stages = []
    for name, stage in named:
        if name == "lut":
            stages.append(LUTLookup(*stage, lut_backend))
        elif isinstance(stage, ColorGrade) and grade_inputs:
            stages.append(GradeWithInputs(stage.aces, stage.curves()))
        else:
            stages.append(stage.export_form() if hasattr(stage, "export_form") else stage)
    if grade_inputs and not any(isinstance(s, GradeWithInputs) for s in stages):
        raise ValueError("grade_inputs=True needs a ColorGrade stage (a look's grade, or a ColorGrade)")
    return ExportGraph(stages, exposure).eval()


def _grade_of(module: nn.Module) -> Optional[ColorGrade]:
    """The grade whose controls feed a ``grade_inputs`` graph: a grade itself, or a look's."""
    if isinstance(module, ColorGrade):
        return module
    if isinstance(module, PostFX):
        return module.grade
    return None


def grade_feeds(grade: Optional[ColorGrade], batch: int) -> dict:
    """Per-sample control tensors of ``grade`` (identity controls for ``None``), for a ``grade_inputs`` model."""
    values = grade.params() if grade is not None else {}
    feeds = {}
    for name, (default, _) in CONTROLS.items():
        shape = (batch,) + torch.as_tensor(default).shape
        value = torch.as_tensor(values.get(name, default), dtype=torch.float32).detach()
        feeds[name] = value if value.shape == shape else value.expand(shape).clone()
    return feeds


def input_names(graph: ExportGraph) -> list:
    """Graph input names, in the order :class:`ExportGraph` takes them."""
    names = ["image"] + (["adapted", "dt"] if graph.exposure is not None else [])
    if any(isinstance(s, GradeWithInputs) for s in graph.stages):
        names += list(CONTROLS)
    return names


def output_names(graph: ExportGraph) -> list:
    return ["output", "adapted_out"] if graph.exposure is not None else ["output"]


def _dynamic_axes(names: Sequence[str]) -> dict:
    axes = {"image": {0: "batch", 2: "height", 3: "width"}, "output": {0: "batch", 2: "height", 3: "width"}}
    axes.update({name: {0: "batch"} for name in names if name not in axes and name != "dt"})
    return axes


def example_inputs(graph: ExportGraph, module: nn.Module, image: torch.Tensor) -> tuple:
    """Inputs to trace ``graph`` with: the image, the exposure state and the grading controls."""
    batch = image.shape[0]
    inputs = [image]
    if graph.exposure is not None:
        inputs += [torch.full((batch,), 0.5), torch.tensor(1.0 / 30.0)]
    if any(isinstance(s, GradeWithInputs) for s in graph.stages):
        # Controls that require grad are never treated as identity, so every grading step is traced.
        inputs += [v.requires_grad_() for v in grade_feeds(_grade_of(module), batch).values()]
    return tuple(inputs)


def default_example(graph: ExportGraph) -> torch.Tensor:
    """A ``(2, 3, 64, 64)`` trace input: every size is taken from runtime shapes, so any size traces."""
    return torch.rand(2, 3, 64, 64, generator=torch.Generator().manual_seed(0)) * 4.0


# ---------------------------------------------------------------- symbolics


def _constant(g, value: float):
    return g.op("Constant", value_t=torch.tensor(value, dtype=torch.float32))


def _exp2(g, x):
    return g.op("Exp", g.op("Mul", x, _constant(g, math.log(2.0))))


def _expm1(g, x):
    return g.op("Sub", g.op("Exp", x), _constant(g, 1.0))


def _rad2deg(g, x):
    return g.op("Mul", x, _constant(g, 180.0 / math.pi))


def _frac(g, x):
    truncated = g.op("Mul", g.op("Sign", x), g.op("Floor", g.op("Abs", x)))
    return g.op("Sub", x, truncated)


def _floor_divide(g, a, b):
    """Python's ``//``, rounding down (the stock symbolic truncates, so ``-(-n // 2)`` came out wrong)."""
    from torch.onnx import symbolic_helper

    if symbolic_helper._is_fp(a) or symbolic_helper._is_fp(b):
        return g.op("Floor", g.op("Div", a, b))
    return g.op("Div", g.op("Sub", a, g.op("Mod", a, b, fmod_i=0)), b)


def _dims(value) -> list:
    from torch.onnx import symbolic_helper

    return torch.as_tensor(symbolic_helper._maybe_get_const(value, "t")).reshape(-1).tolist()


def _movedim(g, x, source, destination):
    """``movedim`` with negative dimensions (the stock symbolic writes them into the permutation)."""
    from torch.onnx import symbolic_helper

    rank = symbolic_helper._get_tensor_rank(x)
    moved = dict(zip((d % rank for d in _dims(destination)), (s % rank for s in _dims(source))))
    rest = iter(d for d in range(rank) if d not in moved.values())
    perm = [moved[d] if d in moved else next(rest) for d in range(rank)]
    return g.op("Transpose", x, perm_i=perm)


def _avg_pool2d(g, x, kernel_size, stride, padding, ceil_mode, count_include_pad, divisor_override):
    """``avg_pool2d``; with ``divisor_override`` (non-overlapping windows, no padding) a zero-padded sum.

    Sums pad the bottom and right edges to a multiple of the window (as ``ceil_mode`` does), average
    with ``AveragePool`` and scale by ``window / divisor``.
    """
    from torch.onnx import symbolic_helper

    kernel = symbolic_helper._maybe_get_const(kernel_size, "is")
    kernel = list(kernel) * 2 if len(kernel) == 1 else list(kernel)
    strides = symbolic_helper._maybe_get_const(stride, "is") or kernel
    strides = list(strides) * 2 if len(strides) == 1 else list(strides)
    pads = symbolic_helper._maybe_get_const(padding, "is")
    pads = list(pads) * 2 if len(pads) == 1 else list(pads)
    ceil = int(symbolic_helper._maybe_get_const(ceil_mode, "b"))
    include_pad = int(symbolic_helper._maybe_get_const(count_include_pad, "b"))
    divisor = None if symbolic_helper._is_none(divisor_override) else symbolic_helper._maybe_get_const(divisor_override, "i")
    if divisor is None:
        return g.op("AveragePool", x, kernel_shape_i=kernel, strides_i=strides, pads_i=pads + pads,
                    ceil_mode_i=ceil, count_include_pad_i=include_pad)
    if kernel != strides or any(pads):
        raise torch.onnx.errors.SymbolicValueError("avg_pool2d with divisor_override: only non-overlapping windows", x)
    window = torch.tensor(kernel, dtype=torch.int64)
    spatial = g.op("Slice", g.op("Shape", x), g.op("Constant", value_t=torch.tensor([2])),
                   g.op("Constant", value_t=torch.tensor([4])))
    window_t = g.op("Constant", value_t=window)
    remainder = g.op("Mod", g.op("Sub", window_t, g.op("Mod", spatial, window_t)), window_t)
    if not ceil:
        remainder = g.op("Mul", remainder, g.op("Constant", value_t=torch.tensor([0, 0])))
    pad_amounts = g.op("Concat", g.op("Constant", value_t=torch.zeros(6, dtype=torch.int64)), remainder, axis_i=0)
    padded = g.op("Pad", x, pad_amounts)
    mean = g.op("AveragePool", padded, kernel_shape_i=kernel, strides_i=strides)
    return g.op("Mul", mean, _constant(g, float(kernel[0] * kernel[1]) / divisor))


_SYMBOLICS = {
    "aten::exp2": _exp2,
    "aten::expm1": _expm1,
    "aten::rad2deg": _rad2deg,
    "aten::frac": _frac,
    "aten::movedim": _movedim,
    "aten::floor_divide": _floor_divide,
    "aten::floordiv": _floor_divide,
    "aten::avg_pool2d": _avg_pool2d,
}


@contextlib.contextmanager
def _symbolics(opset: int):
    """Register torchgrade's symbolic functions for one export, and remove them afterwards."""
    for name, function in _SYMBOLICS.items():
        torch.onnx.register_custom_op_symbolic(name, function, opset)
    try:
        yield
    finally:
        for name in _SYMBOLICS:
            torch.onnx.unregister_custom_op_symbolic(name, opset)


# ---------------------------------------------------------------- export and verification


def export(
    module: nn.Module,
    path,
    *,
    example: Optional[torch.Tensor] = None,
    opset: Optional[int] = None,
    lut_backend: str = "strip",
    grade_inputs: bool = False,
) -> Path:
    """Export a torchgrade module or :class:`~torchgrade.PostFX` look to ``path``; returns the path.

    Args:
        module: any torchgrade module, a ``PostFX`` look, or an ``nn.Module`` built from them that
            maps an image to an image.
        example: image to trace with (default :func:`default_example`); the graph keeps batch,
            height and width dynamic.
        opset: default :data:`DEFAULT_OPSET` (17), or :data:`VOLUME_OPSET` (20) for
            ``lut_backend="volume"``; the volume backend needs at least 20.
        lut_backend: ``"strip"``, ``"gather"`` or ``"volume"`` (see the module docstring).
        grade_inputs: expose the grading controls as graph inputs (see the module docstring).
    """
    minimum = VOLUME_OPSET if lut_backend == "volume" else 16
    opset = opset or (VOLUME_OPSET if lut_backend == "volume" else DEFAULT_OPSET)
    if opset < minimum:
        raise ValueError(f"lut_backend={lut_backend!r} needs opset >= {minimum}, got {opset}")
    graph = export_graph(module, lut_backend, grade_inputs)
    example = default_example(graph) if example is None else example
    inputs = example_inputs(graph, module, example.float())
    names = input_names(graph)
    path = Path(path)
    with _symbolics(opset), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # tracer warnings: Python ints frozen by design (bloom depth)
        torch.onnx.export(
            graph, inputs, str(path), dynamo=False, opset_version=opset,
            input_names=names, output_names=output_names(graph), dynamic_axes=_dynamic_axes(names),
        )
    onnx_lib.checker.check_model(str(path))
    return path


def session(path):
    """An onnxruntime session on the CPU provider."""
    import onnxruntime

    return onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def feeds(runner, module: nn.Module, inputs: Inputs) -> dict:
    """Name the ``inputs`` for ``runner``'s graph; grading-control inputs not given take ``module``'s grade."""
    inputs = (inputs,) if isinstance(inputs, torch.Tensor) else tuple(inputs)
    names = [i.name for i in runner.get_inputs()]
    given = dict(zip(names, inputs))
    missing = [name for name in names if name not in given]
    if missing:
        controls = grade_feeds(_grade_of(module), inputs[0].shape[0])
        given.update({name: controls[name] for name in missing})
    return {name: value.detach().float().numpy() for name, value in given.items()}


def reference(module: nn.Module, inputs: Inputs) -> tuple:
    """PyTorch's outputs for ``inputs`` as the exported graph takes them (stateless for exposure)."""
    inputs = (inputs,) if isinstance(inputs, torch.Tensor) else tuple(inputs)
    with torch.no_grad():
        if isinstance(module, PostFX) and module.exposure is not None:
            return module.frame(*inputs[:3])
        if isinstance(module, AutoExposure):
            return exposure_frame(module, *inputs[:3])
        return (module(inputs[0]),)


def verify(module: nn.Module, path, inputs: Inputs) -> float:
    """Run the ONNX file on onnxruntime (CPU) and return the max abs difference from PyTorch.

    ``inputs`` is the image, or ``(image, adapted, dt)`` for a model with exposure; grading
    controls of a ``grade_inputs`` model default to ``module``'s grade.
    """
    runner = session(path)
    outputs = runner.run(None, feeds(runner, module, inputs))
    expected = reference(module, inputs)
    return max(float(np.max(np.abs(out - exp.float().numpy()))) for out, exp in zip(outputs, expected))


def node_count(path) -> int:
    """Number of nodes in an ONNX file's main graph."""
    return len(onnx_lib.load(str(path), load_external_data=False).graph.node)


def latency_ms(path, inputs: Inputs, module: Optional[nn.Module] = None, repeats: int = 5) -> float:
    """Median wall time (ms) of ``repeats`` onnxruntime runs on ``inputs``, after one warm-up run."""
    runner = session(path)
    named = feeds(runner, module, inputs)
    runner.run(None, named)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        runner.run(None, named)
        times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times)
