"""What an exported file says about itself: doc strings, metadata, and the grading controls' defaults.

Every file carries, in ``metadata_props``: ``torchgrade.version``, ``torchgrade.stages``,
``torchgrade.config`` (the look's config as JSON, what :meth:`~torchgrade.PostFX.from_config` reads;
``null`` for a look baked to a LUT), ``torchgrade.output`` and ``torchgrade.io_dtype`` (how to read the
output), ``color_space.input`` / ``color_space.output``, ``range.input`` / ``range.output``, and for a
``grade_inputs`` model ``torchgrade.grade_inputs``: each control's range and default, as JSON. Each graph
input and output has a doc string saying the same for it.

A ``grade_inputs`` model holds the look's own control values as initializers of the same names as the
inputs: an input not fed takes the look's value (shape ``(1, ...)``, broadcast over the batch; each control's first axis has a size of its own), so a
server feeds only what it changes.

Examples:
    >>> import tempfile, onnx, torchgrade as tg
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = tg.onnx.export(tg.PostFX(tonemap="aces"), folder + "/look.onnx", output="srgb8")
    ...     props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    >>> props["torchgrade.output"], props["torchgrade.config"]
    ('srgb8', '{"tonemap": {"mode": "aces"}}')
"""

from __future__ import annotations

import json

import onnx as onnx_lib  # the onnx package (absolute import), not this package
import torch
from onnx import numpy_helper
from torch import nn

from ..grade import ColorGrade
from .graph import GRADE_INPUTS, OUTPUTS, grade_feeds, grade_of

__all__ = ["INPUT_DOCS", "look_config", "describe"]

INPUT_DOCS = {
    "image": "scene-linear RGB, Rec.709 primaries (D65), (batch, 3, height, width); HDR, unbounded above; "
             "non-finite values are sanitized (torchgrade.core.sanitize)",
    "adapted": "previous frame's adapted luminance per sample, (batch,); <= 0 starts a sequence",
    "dt": "seconds since the previous frame, a scalar",
}
"""Doc strings of the graph inputs other than the grading controls."""


def look_config(module: nn.Module):
    """The config a look (or single stage) is rebuilt from, or ``None`` where it has none (a baked LUT).

    Examples:
        >>> import torchgrade as tg
        >>> look_config(tg.PostFX(tonemap="neutral"))
        {'tonemap': {'mode': 'neutral'}}
    """
    to_config = getattr(module, "to_config", None)
    try:
        return to_config() if to_config is not None else None
    except ValueError:  # a look baked to a LUT: the table is the look
        return None


def _control_doc(name: str, default) -> str:
    low, high = ColorGrade.controls[name].range
    return (f"ColorGrade {name} in Unity's units, (batch, ...) or (1, ...); clamped to [{low}, {high}]; "
            f"optional, default the look's value {json.dumps(default)}")


def _add_defaults(graph: onnx_lib.GraphProto, module: nn.Module) -> dict:
    """The look's control values as initializers beside the inputs of the same name; ``{name: default}``."""
    values = {name: value.numpy() for name, value in grade_feeds(grade_of(module), 1).items()}
    del graph.value_info[:]  # traced intermediate shapes assumed a batch-sized control; runtimes infer them again
    for graph_input in graph.input:
        if graph_input.name in values:
            graph.initializer.append(numpy_helper.from_array(values[graph_input.name], graph_input.name))
    return {name: value[0].tolist() for name, value in values.items()}


def describe(model: onnx_lib.ModelProto, module: nn.Module, output: str, io_dtype: torch.dtype) -> onnx_lib.ModelProto:
    """Write doc strings and metadata into ``model`` (and defaults for grading-control inputs); returns it."""
    from .. import __version__  # the package sets it after importing this module
    graph = model.graph
    names = {graph_input.name for graph_input in graph.input}
    defaults = _add_defaults(graph, module) if names & set(GRADE_INPUTS) else {}
    dtype = str(io_dtype).replace("torch.", "")
    for graph_input in graph.input:
        graph_input.doc_string = INPUT_DOCS.get(graph_input.name) or _control_doc(graph_input.name, defaults[graph_input.name])
        if graph_input.name == "image":
            graph_input.doc_string += f"; {dtype}"
    output_doc = f"{OUTPUTS[output]}; (batch, 3, height, width)" + ("" if output == "srgb8" else f"; {dtype}")
    graph.output[0].doc_string = output_doc
    for extra in graph.output[1:]:
        extra.doc_string = "adapted luminance per sample for the next frame's 'adapted' input, (batch,)"
    stages = list(module.stages()) if callable(getattr(module, "stages", None)) else [type(module).__name__]
    model.doc_string = f"torchgrade {__version__} look: {' -> '.join(stages)}. Output: {output_doc}."
    metadata = {
        "torchgrade.version": __version__, "torchgrade.stages": json.dumps(stages),
        "torchgrade.config": json.dumps(look_config(module)), "torchgrade.output": output, "torchgrade.io_dtype": dtype,
        "color_space.input": "scene-linear Rec.709 primaries, D65", "range.input": INPUT_DOCS["image"],
        "color_space.output": "Rec.709 primaries, D65, " + ("linear" if output == "linear" else "sRGB transfer"),
        "range.output": OUTPUTS[output],
    }
    if defaults:
        ranges = {name: list(ColorGrade.controls[name].range) for name in defaults}
        metadata["torchgrade.grade_inputs"] = json.dumps({n: {"range": ranges[n], "default": defaults[n]} for n in defaults})
    onnx_lib.helper.set_model_props(model, metadata)
    return model
