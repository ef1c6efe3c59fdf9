"""What an exported file says about itself: doc strings, metadata, and the defaults of its optional inputs.

Every file carries, in ``metadata_props``: ``torchgrade.version``, ``torchgrade.stages``,
``torchgrade.config`` (:data:`CONFIG_KEY`: the look's config as JSON, what :meth:`~torchgrade.PostFX.from_config`
reads; ``null`` for a look baked to a LUT), how frames come in and go out (``torchgrade.input_dtype``,
``torchgrade.layout``, ``torchgrade.output``, ``torchgrade.io_dtype``, ``torchgrade.output_layout``:
:func:`~torchgrade.onnx.frames.read_frame_format` reads them), ``color_space.input`` / ``color_space.output``,
``range.input`` / ``range.output``, and for a ``grade_inputs`` model ``torchgrade.grade_inputs``: each control's
range and default, as JSON. Each graph input and output has a doc string saying the same for it.

The grading controls of a ``grade_inputs`` model (the look's own values, shape ``(1, ...)``, broadcast over the
batch; each control's first axis has a size of its own) and a look's ``adapted`` and ``dt`` (instant adaptation,
:data:`~torchgrade.onnx.defaults.STATE_DEFAULTS`) are optional inputs with those defaults
(:mod:`~torchgrade.onnx.defaults`), so a server feeds only what it changes.

Examples:
    >>> import tempfile, onnx, torchgrade as tg
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = tg.onnx.export(tg.PostFX(tonemap="aces"), folder + "/look.onnx", output="srgb8")
    ...     props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    >>> props["torchgrade.output"], props["torchgrade.config"], props["torchgrade.layout"]
    ('srgb8', '{"tonemap": {"mode": "aces"}}', 'NCHW')
"""

from __future__ import annotations

import json

import onnx as onnx_lib  # the onnx package (absolute import), not this package
from torch import nn

from ..grading.layer import ColorGrade
from .defaults import STATE_DEFAULTS, with_defaults
from .frames import CODE_MAX, OUTPUTS, FrameFormat, metadata_of
from .graph import GRADE_INPUTS, grade_feeds, grade_of

__all__ = ["CONFIG_KEY", "FORMER_CONFIG_KEY", "INPUT_DOCS", "look_config", "describe"]

CONFIG_KEY = "torchgrade.config"
"""The metadata key of the look's config."""

FORMER_CONFIG_KEY = "torchgrade.base.config"
"""The key files exported by an earlier version of the package hold the config under
(:func:`~torchgrade.onnx.verify.metadata` reads it as :data:`CONFIG_KEY`)."""

INPUT_DOCS = {
    "image": "scene-linear RGB, Rec.709 primaries (D65); HDR, unbounded above; "
             "non-finite values are sanitized (torchgrade.base.images.sanitize)",
    "adapted": "previous frame's adapted luminance per sample, (batch,); <= 0 starts a sequence (instant adaptation)",
    "dt": "seconds since the previous frame, a scalar",
}
"""Doc strings of the graph inputs other than the grading controls (a float image's; integer codes are described
from the file's :class:`~torchgrade.onnx.frames.FrameFormat`)."""


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


def _control_doc(name: str) -> str:
    low, high = ColorGrade.controls[name].range
    return f"ColorGrade {name} in Unity's units, (batch, ...) or (1, ...); clamped to [{low}, {high}]"


def _shape(layout: str) -> str:
    return "(batch, 3, height, width)" if layout == "NCHW" else "(batch, height, width, 3)"


def _image_doc(frames: FrameFormat) -> str:
    dtype = str(frames.input_dtype).replace("torch.", "")
    if frames.input_dtype in CODE_MAX:
        return (f"sRGB-encoded RGB code values ({dtype}, 0-{CODE_MAX[frames.input_dtype]}), Rec.709 primaries (D65), "
                f"decoded to linear light in the graph (IEC 61966-2-1), {_shape(frames.layout)}")
    return f"{INPUT_DOCS['image']}, {_shape(frames.layout)}; {dtype}"


def _defaults(graph: onnx_lib.GraphProto, module: nn.Module) -> dict:
    """``{input name: default array}`` of the inputs that have a default (:mod:`~torchgrade.onnx.defaults`)."""
    names = {graph_input.name for graph_input in graph.input}
    defaults = {name: value for name, value in STATE_DEFAULTS.items() if name in names}
    if names & set(GRADE_INPUTS):
        defaults.update({name: value.numpy() for name, value in grade_feeds(grade_of(module), 1).items()})
    return defaults


def describe(model: onnx_lib.ModelProto, module: nn.Module, frames: FrameFormat = FrameFormat(),
             optional_inputs: bool = True) -> onnx_lib.ModelProto:
    """Write doc strings and metadata into ``model``, and make the inputs that have defaults optional
    (``optional_inputs=False``: plain inputs, fed on every call); returns it."""
    from .. import __version__  # the package sets it after importing this module
    graph = model.graph
    defaults = _defaults(graph, module)
    if defaults:
        del graph.value_info[:]  # traced intermediate shapes assumed batch-sized inputs; runtimes infer them again
    for graph_input in graph.input:
        name = graph_input.name
        graph_input.doc_string = _image_doc(frames) if name == "image" else INPUT_DOCS.get(name) or _control_doc(name)
        if name in defaults:
            value = json.dumps(defaults[name].tolist() if defaults[name].ndim == 0 else defaults[name][0].tolist())
            graph_input.doc_string += f"; optional, default {value}" if optional_inputs else f"; fed on every call (default value {value})"
    with_defaults(model, defaults, optional_inputs)
    output_doc = f"{OUTPUTS[frames.output]}; {_shape(frames.output_layout)}"
    if frames.output not in ("srgb8", "srgb16"):
        output_doc += f"; {str(frames.float_dtype).replace('torch.', '')}"
    graph.output[0].doc_string = output_doc
    for extra in graph.output[1:]:
        extra.doc_string = "adapted luminance per sample for the next frame's 'adapted' input, (batch,)"
    listed = getattr(module, "stages", None)
    stages = list(listed()) if callable(listed) else [type(module).__name__]
    model.doc_string = f"torchgrade {__version__} look: {' -> '.join(stages)}. Output: {output_doc}."
    encoded = frames.input_dtype in CODE_MAX
    metadata = {
        "torchgrade.version": __version__, "torchgrade.stages": json.dumps(stages),
        CONFIG_KEY: json.dumps(look_config(module)), **metadata_of(frames),
        "color_space.input": ("sRGB-encoded, decoded to linear in the graph, " if encoded else "scene-linear ") + "Rec.709 primaries, D65",
        "range.input": _image_doc(frames),
        "color_space.output": "Rec.709 primaries, D65, " + ("linear" if frames.output == "linear" else "sRGB transfer"),
        "range.output": OUTPUTS[frames.output],
    }
    grade = {name: defaults[name][0].tolist() for name in GRADE_INPUTS if name in defaults}
    if grade:
        ranges = {name: list(ColorGrade.controls[name].range) for name in grade}
        metadata["torchgrade.grade_inputs"] = json.dumps({n: {"range": ranges[n], "default": grade[n]} for n in grade})
    onnx_lib.helper.set_model_props(model, metadata)
    return model
