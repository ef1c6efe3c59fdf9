"""The per-pixel end of an exported look run on strips of rows, in an ONNX ``Scan``, as eager runs it (:func:`~torchgrade.runtime.in_strips`).

A per-pixel stage is dozens of elementwise nodes; on a whole 1080p frame each node reads and writes
24 MiB from memory. :func:`mark` ends the traced head of the look (exposure, bloom; for a look that is per pixel
from its input, nothing: the input's decoding runs in the strips too) with a marker node, ``mark(..., end=True)``
ends the per-pixel part (the output's layout is the whole frame's), and :func:`scan_strips` moves every node
between the two into the body of a ``Scan`` over strips of about :data:`SCAN_STRIP_PIXELS` pixels, so a strip's
intermediates stay in cache. The frame is
padded with zero rows to a whole number of strips and the padding is sliced off the output; the strip
height follows the runtime shape (one strip for a frame up to that size), so one file serves every size.

Examples:
    >>> import onnx
    >>> from onnx import TensorProto, helper
    >>> graph = helper.make_graph(
    ...     [helper.make_node("Strips", ["image"], ["strip"], domain=DOMAIN), helper.make_node("Sqrt", ["strip"], ["root"]),
    ...      helper.make_node("StripsEnd", ["root"], ["frame"], domain=DOMAIN), helper.make_node("Neg", ["frame"], ["output"])],
    ...     "g", [helper.make_tensor_value_info("image", TensorProto.FLOAT, ["n", 3, "h", "w"])],
    ...     [helper.make_tensor_value_info("output", TensorProto.FLOAT, ["n", 3, "h", "w"])],
    ...     value_info=[helper.make_tensor_value_info("strip", TensorProto.FLOAT, None)])  # as the exporter types a marker
    >>> model = scan_strips(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17), helper.make_opsetid(DOMAIN, 1)]))
    >>> scan, = [node for node in model.graph.node if node.op_type == "Scan"]
    >>> [node.op_type for node in helper.get_attribute_value(scan.attribute[0]).node], model.graph.node[-1].op_type
    (['Sqrt'], 'Neg')
"""

from __future__ import annotations

import numpy as np
import onnx as onnx_lib  # the onnx package (absolute import), not this package
import torch
from onnx import helper, numpy_helper

__all__ = ["DOMAIN", "SCAN_STRIP_PIXELS", "mark", "scan_strips"]

SCAN_STRIP_PIXELS = 1 << 17
"""Pixels per strip of the ``Scan`` (batch included): eager PyTorch's strip on two threads
(:data:`~torchgrade.runtime.policy.STRIP_PIXELS_PER_THREAD` each), the size ``benchmarks/bench_onnx.py`` measured the
exported look's strips at."""

DOMAIN = "torchgrade"
"""Domain of the marker node :func:`mark` writes (no runtime reads it: :func:`scan_strips` replaces it)."""


class _Marker(torch.autograd.Function):
    """Identity in PyTorch; a ``torchgrade::Strips`` (or ``StripsEnd``) node in the traced graph."""

    @staticmethod
    def forward(ctx, image, end):
        return image.clone()

    @staticmethod
    def symbolic(g, image, end):
        return g.op(f"{DOMAIN}::{'StripsEnd' if end else 'Strips'}", image).setType(image.type())


def mark(image: torch.Tensor, end: bool = False) -> torch.Tensor:
    """``image``, marked in an ONNX export as where the per-pixel stages begin (or, ``end=True``, end; see the
    module docstring).

    Examples:
        >>> bool(torch.equal(mark(torch.ones(2)), torch.ones(2)))
        True
    """
    return _Marker.apply(image, end) if torch.onnx.is_in_onnx_export() else image


def _downstream(nodes: list, start: str) -> list:
    """The nodes that depend on tensor ``start``, in graph order."""
    reached, body = {start}, []
    for node in nodes:
        if reached.intersection(node.input):
            body.append(node)
            reached.update(node.output)
    return body


def _constants_of(nodes: list, body: list) -> list:
    """``Constant`` nodes read by ``body`` and by no other node of ``nodes``."""
    inside = {id(node) for node in body}
    read_outside = {name for node in nodes if id(node) not in inside for name in node.input}
    read_inside = {name for node in body for name in node.input}
    return [node for node in nodes if node.op_type == "Constant" and id(node) not in inside
            and node.output[0] in read_inside and node.output[0] not in read_outside]


def _element_types(model: onnx_lib.ModelProto) -> dict:
    """``{tensor name: ONNX element type}`` of the main graph's inputs, initializers and inferred intermediates."""
    graph = onnx_lib.shape_inference.infer_shapes(model).graph
    types = {info.name: info.type.tensor_type.elem_type for info in [*graph.input, *graph.value_info]}
    types.update({init.name: init.data_type for init in graph.initializer})
    types.update({node.output[0]: node.attribute[0].t.data_type for node in graph.node if node.op_type == "Constant"})
    return types


def _carried(body: list, produced: set, types: dict) -> tuple:
    """The values ``body`` reads from the outer graph, passed in as the ``Scan``'s state variables (OpenVINO's
    ``Scan`` reads no outer-scope names): ``(outer names, body inputs, Identity nodes, body outputs)``, the
    body's nodes renamed to read the inputs."""
    outer = list(dict.fromkeys(name for node in body for name in node.input if name and name not in produced))
    renamed = {name: f"{name}_strip_state" for name in outer}
    for node in body:
        node.input[:] = [renamed.get(name, name) for name in node.input]
    inputs = [helper.make_tensor_value_info(renamed[name], types[name], None) for name in outer]
    identities = [helper.make_node("Identity", [renamed[name]], [f"{name}_strip_kept"]) for name in outer]
    outputs = [helper.make_tensor_value_info(f"{name}_strip_kept", types[name], None) for name in outer]
    return outer, inputs, identities, outputs


def _int64(name: str, values) -> onnx_lib.TensorProto:
    return numpy_helper.from_array(np.asarray(values, dtype=np.int64), name)


def _ceil_div(numerator: str, denominator: str, one: str, quotient: str) -> list:
    """Nodes computing the int64 ``quotient = ceil(numerator / denominator) = (numerator + denominator - 1) / denominator``."""
    return [helper.make_node("Sub", [denominator, one], [quotient + "_less"]),
            helper.make_node("Add", [numerator, quotient + "_less"], [quotient + "_up"]),
            helper.make_node("Div", [quotient + "_up", denominator], [quotient])]


def _strip_plumbing(frame: str, strips: str) -> tuple:
    """Nodes and constants that pad ``frame`` ``(n, c, h, w)`` with zero rows and reshape it into ``strips``
    ``(n, c, count, rows, w)``: ``rows = ceil(h / count)`` with ``count = ceil(h / min(h, max(1, SCAN_STRIP_PIXELS // (n w))))``.
    Also returns the names of ``h`` and ``w`` (1-D) that the output's reassembly needs."""
    p = "strips_"
    constants = [_int64(p + "one", [1]), _int64(p + "pixels", [SCAN_STRIP_PIXELS]), _int64(p + "no_pads", [0] * 6),
                 _int64(p + "zero", [0]), _int64(p + "n", [0]), _int64(p + "c", [1]), _int64(p + "h", [2]), _int64(p + "w", [3])]
    node = helper.make_node
    nodes = [
        node("Shape", [frame], [p + "shape"]),
        *(node("Gather", [p + "shape", p + axis], [p + axis + "_size"], axis=0) for axis in "nchw"),
        node("Mul", [p + "n_size", p + "w_size"], [p + "row_pixels"]),
        node("Div", [p + "pixels", p + "row_pixels"], [p + "fit"]),
        node("Max", [p + "fit", p + "one"], [p + "fit_one"]),
        node("Min", [p + "fit_one", p + "h_size"], [p + "most_rows"]),
        *_ceil_div(p + "h_size", p + "most_rows", p + "one", p + "count"),
        *_ceil_div(p + "h_size", p + "count", p + "one", p + "rows"),
        node("Mul", [p + "rows", p + "count"], [p + "padded"]),
        node("Sub", [p + "padded", p + "h_size"], [p + "pad"]),
        node("Concat", [p + "no_pads", p + "pad", p + "zero"], [p + "pads"], axis=0),
        node("Pad", [frame, p + "pads"], [p + "frame"]),
        node("Concat", [p + "n_size", p + "c_size", p + "count", p + "rows", p + "w_size"], [p + "shape5"], axis=0),
        node("Reshape", [p + "frame", p + "shape5"], [strips]),
    ]
    return nodes, constants, p + "h_size", p + "w_size"


def _reassembly(strips: str, height: str, width: str, output: str) -> tuple:
    """Nodes that reshape ``strips`` ``(n, c, count, rows, w)`` to ``(n, c, count rows, w)`` and slice the first ``height`` rows."""
    p = "strips_out_"
    constants = [_int64(p + "keep", [0, 0, -1]), _int64(p + "zero", [0]), _int64(p + "axis", [2])]
    nodes = [
        helper.make_node("Concat", [p + "keep", width], [p + "shape"], axis=0),
        helper.make_node("Reshape", [strips, p + "shape"], [p + "padded"]),
        helper.make_node("Slice", [p + "padded", p + "zero", height, p + "axis"], [output]),
    ]
    return nodes, constants


def scan_strips(model: onnx_lib.ModelProto) -> onnx_lib.ModelProto:
    """Move the nodes between the ``Strips`` and ``StripsEnd`` markers into a ``Scan`` over strips of rows (see the
    module docstring); a model without markers is returned as it is."""
    types = _element_types(model)
    graph = model.graph
    nodes = list(graph.node)
    markers = {node.op_type: node for node in nodes if node.domain == DOMAIN}
    if not markers:
        return model
    if sorted(markers) != ["Strips", "StripsEnd"]:
        raise ValueError(f"strips need one Strips and one StripsEnd marker, got {sorted(markers)}")
    start, end = markers["Strips"], markers["StripsEnd"]
    frame, strip, result = start.input[0], start.output[0], end.input[0]
    after = _downstream(nodes, end.output[0])
    outside = {id(node) for node in after} | {id(end)}
    body_nodes = [node for node in _downstream(nodes, strip) if id(node) not in outside]
    if result not in {name for node in body_nodes for name in node.output}:
        raise ValueError(f"the nodes after the strip marker do not produce the end marker's input {result!r}")
    body_nodes = _constants_of(nodes, body_nodes) + body_nodes
    produced = {strip} | {name for node in body_nodes for name in node.output}
    outer, state_inputs, identities, state_outputs = _carried(body_nodes, produced, types)
    body = helper.make_graph(
        body_nodes + identities, "strip",
        state_inputs + [helper.make_tensor_value_info(strip, types[frame], [None] * 4)],
        state_outputs + [helper.make_tensor_value_info(result, types[result], [None] * 4)])
    plumbing, constants, height, width = _strip_plumbing(frame, "strips_in")
    scan = helper.make_node("Scan", outer + ["strips_in"], [f"{name}_strips_last" for name in outer] + ["strips_out"],
                            body=body, num_scan_inputs=1, scan_input_axes=[2], scan_output_axes=[2])
    reassembly, out_constants = _reassembly("strips_out", height, width, end.output[0])
    moved = {id(node) for node in body_nodes} | {id(start)} | outside
    kept = [node for node in nodes if id(node) not in moved]
    del graph.node[:]
    graph.node.extend(kept + plumbing + [scan] + reassembly + after)
    graph.initializer.extend(constants + out_constants)
    del graph.value_info[:]  # traced shapes name the frame's height where the body sees a strip's
    imports = [opset for opset in model.opset_import if opset.domain != DOMAIN]
    del model.opset_import[:]
    model.opset_import.extend(imports)
    return model
