"""``export``: one ONNX file per look, with dynamic batch, height and width.

Examples:
    >>> import tempfile, torchgrade as tg
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = export(tg.ToneMap("reinhard"), folder + "/tonemap.onnx")
    ...     print(path.suffix)
    .onnx
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Optional, Sequence

import onnx as onnx_lib  # the onnx package (absolute import), not this package
import torch
from torch import nn

from ..base.images import check_on_cpu
from ..io.atomic import atomic_write
from ..lut import BACKENDS
from ..lut.backends import backend_named
from .describe import describe
from .frames import FLOAT_DTYPES, FrameFormat, frame_format, retype_uint16
from .graph import (
    GRADE_INPUTS,
    default_example,
    example_inputs,
    export_graph,
    input_names,
    output_names,
)
from .strips import scan_strips
from .symbolics import symbolics
from .verify import graph_nodes

__all__ = ["DEFAULT_OPSET", "VOLUME_OPSET", "IO_DTYPES", "fold_constants", "used_opsets", "export"]

IO_DTYPES = FLOAT_DTYPES
"""Dtypes of a float image input and a float output (the graph computes in float32 either way)."""

DEFAULT_OPSET = 17
"""Opset of every export unless a 5-D GridSample LUT asks for :data:`VOLUME_OPSET`."""
VOLUME_OPSET = BACKENDS["volume"]
"""First opset with 5-D ``GridSample`` (mode spelled ``"linear"``)."""


def _dynamic_axes(names: Sequence[str], frames: FrameFormat) -> dict:
    sizes = {"NCHW": {0: "batch", 2: "height", 3: "width"}, "NHWC": {0: "batch", 1: "height", 2: "width"}}
    axes = {"image": sizes[frames.layout], "output": sizes[frames.output_layout]}
    axes.update({name: {0: "batch"} for name in names if name not in axes and name not in GRADE_INPUTS and name != "dt"})
    # A control of its own size (batch or 1): one fed per sample while another keeps its (1, ...) default.
    axes.update({name: {0: f"{name}_batch"} for name in names if name in GRADE_INPUTS})
    return axes


def fold_constants(path) -> None:
    """Rewrite ``path`` with onnxruntime's basic graph optimisations: constant folding and redundant-node
    elimination, standard ONNX operators only (so OpenVINO and TensorRT read the result). The exporter
    leaves the shape arithmetic of a dynamic-size graph as thousands of ``Constant`` nodes: the
    cinematic look goes from 5691 nodes to 2271.

    Examples:
        >>> callable(fold_constants)
        True
    """
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.graph_optimization_level = onnxruntime.GraphOptimizationLevel.ORT_ENABLE_BASIC
    options.optimized_model_filepath = str(path)
    onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def used_opsets(model: onnx_lib.ModelProto) -> onnx_lib.ModelProto:
    """Keep only the ``opset_import`` entries of domains a node uses (the standard one always): onnxruntime's
    optimised file declares its own nine (``com.microsoft``, ``org.pytorch.aten``, ...) whatever the nodes are.

    Examples:
        >>> from onnx import helper
        >>> graph = helper.make_graph([helper.make_node("Relu", ["x"], ["y"])], "g", [], [])
        >>> model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17), helper.make_opsetid("com.microsoft", 1)])
        >>> [opset.domain for opset in used_opsets(model).opset_import]
        ['']
    """
    domains = {""} | {node.domain for node in graph_nodes(model.graph)}
    kept = [opset for opset in model.opset_import if opset.domain in domains]
    del model.opset_import[:]
    model.opset_import.extend(kept)
    return model


def export(module: nn.Module, path, *, example: Optional[torch.Tensor] = None, opset: Optional[int] = None,
           lut_backend: str = "slices", grade_inputs: bool = False, output: str = "linear",
           io_dtype: torch.dtype = torch.float32, input_dtype: Optional[torch.dtype] = None, layout: str = "NCHW",
           output_layout: Optional[str] = None, optional_inputs: bool = True, fold: bool = True, strips: bool = True) -> Path:
    """Export a torchgrade module or :class:`~torchgrade.PostFX` look to ``path``; returns the path.

    Args:
        module: any torchgrade module, a ``PostFX`` look, or an ``nn.Module`` built from them that
            maps an image to an image.
        example: image to trace with, as the look takes it (float ``(batch, 3, height, width)``, default
            :func:`~torchgrade.onnx.default_example`); the graph keeps batch, height and width dynamic.
        opset: default :data:`DEFAULT_OPSET` (17), or :data:`VOLUME_OPSET` (20) for
            ``lut_backend="volume"``; each backend needs at least its opset in
            :data:`~torchgrade.lut.BACKENDS`.
        lut_backend: ``"slices"``, ``"gather"`` or ``"volume"`` (see :data:`~torchgrade.lut.BACKENDS`).
        grade_inputs: expose the grading controls as graph inputs (see :mod:`torchgrade.onnx`), optional
            (the look's values are their defaults) and clamped to their ranges.
        output: the output encoding, one of :data:`~torchgrade.onnx.OUTPUTS` (``"linear"``, ``"srgb"``, ``"srgb8"``,
            ``"srgb16"``).
        io_dtype: the dtype of a float image input and a float output (:data:`IO_DTYPES`).
        input_dtype: the image input's dtype (default ``io_dtype``): ``torch.float32`` or ``torch.float16``
            scene-linear, ``torch.uint8`` or ``torch.uint16`` sRGB codes decoded to linear in the graph
            (:mod:`~torchgrade.onnx.frames`).
        layout: the image input's layout, ``"NCHW"`` ``(batch, 3, height, width)`` or ``"NHWC"`` ``(batch, height, width, 3)``;
            ``output_layout`` the output's (default ``layout``).
        optional_inputs: ``adapted``, ``dt`` and the grading controls as optional inputs with defaults
            (:mod:`~torchgrade.onnx.defaults`; onnxruntime); ``False`` writes them as plain inputs fed on every call,
            for runtimes without ONNX optional types (OpenVINO, TensorRT).
        fold: fold constants (:func:`fold_constants`); ``False`` keeps the exporter's graph as traced.
        strips: run the stages that end the look and are per pixel (grade, tone mapping, LUT, output encoding)
            on strips of rows in a ``Scan`` (:mod:`~torchgrade.onnx.strips`); ``False`` runs them on the whole frame.

    Examples:
        >>> import torchgrade as tg
        >>> export(tg.ToneMap(), "never.onnx", lut_backend="volume", opset=17)
        Traceback (most recent call last):
        ...
        ValueError: lut_backend='volume' needs opset >= 20, got 17
    """
    check_on_cpu(module, "tg.onnx.export")
    lut_backend = backend_named(lut_backend)
    minimum = BACKENDS[lut_backend]
    opset = opset or max(DEFAULT_OPSET, minimum)
    if opset < minimum:
        raise ValueError(f"lut_backend={lut_backend!r} needs opset >= {minimum}, got {opset}")
    frames = frame_format(input_dtype, layout, output, io_dtype, output_layout)
    graph = export_graph(module, lut_backend, grade_inputs, frames, strips)
    example = default_example(graph) if example is None else example
    inputs = example_inputs(graph, module, example)
    names = input_names(graph)

    def write(temporary: str) -> None:
        with symbolics(opset), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # tracer warnings: Python ints frozen by design (bloom depth)
            torch.onnx.export(
                graph, inputs, temporary, dynamo=False, opset_version=opset,
                input_names=names, output_names=output_names(graph), dynamic_axes=_dynamic_axes(names, frames),
            )
        model = retype_uint16(onnx_lib.load(temporary), frames)
        onnx_lib.save(scan_strips(model) if strips else model, temporary)
        if fold:
            fold_constants(temporary)
        model = used_opsets(onnx_lib.load(temporary))
        onnx_lib.save(describe(model, module, frames, optional_inputs), temporary)
        onnx_lib.checker.check_model(temporary)

    # Every step rewrites the file: they work on a temporary one beside it, renamed onto the target only when the
    # model is whole and checked, so a full disk or a failed step leaves the old file as it was.
    atomic_write(path, write)
    return Path(path)
