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

from ..core import check_on_cpu
from ..io.atomic import atomic_write
from ..lut import BACKENDS
from .describe import describe
from .graph import GRADE_INPUTS, default_example, example_inputs, export_graph, input_names, output_names
from .strips import scan_strips
from .symbolics import symbolics

__all__ = ["DEFAULT_OPSET", "VOLUME_OPSET", "IO_DTYPES", "fold_constants", "export"]

IO_DTYPES = (torch.float32, torch.float16)
"""Dtypes of the image input and float output (the graph computes in float32 either way)."""

DEFAULT_OPSET = 17
"""Opset of every export unless a 5-D GridSample LUT asks for :data:`VOLUME_OPSET`."""
VOLUME_OPSET = BACKENDS["volume"]
"""First opset with 5-D ``GridSample`` (mode spelled ``"linear"``)."""


def _dynamic_axes(names: Sequence[str]) -> dict:
    axes = {"image": {0: "batch", 2: "height", 3: "width"}, "output": {0: "batch", 2: "height", 3: "width"}}
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


def export(module: nn.Module, path, *, example: Optional[torch.Tensor] = None, opset: Optional[int] = None,
           lut_backend: str = "strip", grade_inputs: bool = False, output: str = "linear",
           io_dtype: torch.dtype = torch.float32, fold: bool = True, strips: bool = True) -> Path:
    """Export a torchgrade module or :class:`~torchgrade.PostFX` look to ``path``; returns the path.

    Args:
        module: any torchgrade module, a ``PostFX`` look, or an ``nn.Module`` built from them that
            maps an image to an image.
        example: image to trace with (default :func:`~torchgrade.onnx.default_example`); the graph
            keeps batch, height and width dynamic.
        opset: default :data:`DEFAULT_OPSET` (17), or :data:`VOLUME_OPSET` (20) for
            ``lut_backend="volume"``; each backend needs at least its opset in
            :data:`~torchgrade.lut.BACKENDS`.
        lut_backend: ``"strip"``, ``"gather"`` or ``"volume"`` (see :data:`~torchgrade.lut.BACKENDS`).
        grade_inputs: expose the grading controls as graph inputs (see :mod:`torchgrade.onnx`), optional
            (the look's values are their defaults) and clamped to their ranges.
        output: the output encoding, one of :data:`~torchgrade.onnx.OUTPUTS` (``"linear"``, ``"srgb"``, ``"srgb8"``).
        io_dtype: the image input's and float output's dtype (:data:`IO_DTYPES`).
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
    minimum = BACKENDS.get(lut_backend, 0)
    opset = opset or max(DEFAULT_OPSET, minimum)
    if opset < minimum:
        raise ValueError(f"lut_backend={lut_backend!r} needs opset >= {minimum}, got {opset}")
    if io_dtype not in IO_DTYPES:
        raise ValueError(f"io_dtype must be one of {IO_DTYPES}, got {io_dtype}")
    graph = export_graph(module, lut_backend, grade_inputs, output, strips)
    example = default_example(graph) if example is None else example
    inputs = example_inputs(graph, module, example.to(io_dtype))
    names = input_names(graph)

    def write(temporary: str) -> None:
        with symbolics(opset), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # tracer warnings: Python ints frozen by design (bloom depth)
            torch.onnx.export(
                graph, inputs, temporary, dynamo=False, opset_version=opset,
                input_names=names, output_names=output_names(graph), dynamic_axes=_dynamic_axes(names),
            )
        if strips:
            onnx_lib.save(scan_strips(onnx_lib.load(temporary)), temporary)
        if fold:
            fold_constants(temporary)
        onnx_lib.save(describe(onnx_lib.load(temporary), module, output, io_dtype), temporary)
        onnx_lib.checker.check_model(temporary)

    # Every step rewrites the file: they work on a temporary one beside it, renamed onto the target only when the
    # model is whole and checked, so a full disk or a failed step leaves the old file as it was.
    atomic_write(path, write)
    return Path(path)
