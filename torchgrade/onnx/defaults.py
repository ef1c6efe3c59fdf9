"""Graph inputs a caller may leave out: ONNX optional inputs, each with its default in the graph.

An input ``x`` with a default has the type ``optional(tensor(float))``; the graph reads
``If(OptionalHasElement(x), OptionalGetElement(x), default)``. onnxruntime lists such an input in
``get_inputs()`` and runs without it (feeding it is feeding an array, as for any input). The other way ONNX has
to give an input a default, an initializer of the input's name, hides the input in onnxruntime's
``get_overridable_initializers()`` (so a server config written from ``get_inputs()`` misses it), costs a warning per
input and session ("Initializer x appears in graph inputs") and is read by OpenVINO 2026.4 as a constant.

OpenVINO 2026.4 reads no optional type ("Model wasn't fully converted"), nor does TensorRT: :func:`plain_inputs`
gives the form where every input is a plain tensor (what :class:`~torchgrade.onnx.OpenVINOSession` compiles, feeding
the defaults itself), and ``tg.onnx.export(..., optional_inputs=False)`` writes that form.

Examples:
    >>> from onnx import TensorProto, helper
    >>> graph = helper.make_graph([helper.make_node("Mul", ["image", "gain"], ["output"])], "g",
    ...     [helper.make_tensor_value_info(name, TensorProto.FLOAT, None) for name in ("image", "gain")],
    ...     [helper.make_tensor_value_info("output", TensorProto.FLOAT, None)])
    >>> model = with_defaults(helper.make_model(graph), {"gain": np.array([2.0], np.float32)})
    >>> [node.op_type for node in model.graph.node]
    ['OptionalHasElement', 'If', 'Mul']
    >>> plain, defaults = plain_inputs(model)
    >>> [node.op_type for node in plain.graph.node], defaults["gain"].tolist()
    (['Identity', 'Mul'], [2.0])
"""

from __future__ import annotations

import copy

import numpy as np
import onnx as onnx_lib  # the onnx package (absolute import), not this package
from onnx import helper, numpy_helper

__all__ = ["STATE_DEFAULTS", "with_defaults", "optional_names", "plain_inputs"]

STATE_DEFAULTS = {"adapted": np.zeros(1, np.float32), "dt": np.array(0.0, np.float32)}
"""Defaults of the inputs of a look with eye adaptation: instant adaptation (an adapted luminance of 0 starts a
sequence, whatever ``dt``), what a still or the first frame of a shot needs; video feeds both."""


def with_defaults(model: onnx_lib.ModelProto, defaults: dict, optional: bool = True) -> onnx_lib.ModelProto:
    """Make each input of ``model`` named in ``defaults`` (``{name: array}``) optional, reading its default when
    not fed; ``optional=False`` leaves the inputs as they are (plain, fed every call). Returns ``model``."""
    if not optional:
        return model
    graph = model.graph
    added = []
    for graph_input in graph.input:
        name = graph_input.name
        if name not in defaults:
            continue
        value = f"{name}_or_default"
        for node in graph.node:
            node.input[:] = [value if used == name else used for used in node.input]
        fed = helper.make_graph([helper.make_node("OptionalGetElement", [name], [f"{name}_fed"])], f"{name}_fed", [],
                                [helper.make_tensor_value_info(f"{name}_fed", onnx_lib.TensorProto.FLOAT, None)])
        default = helper.make_graph(
            [helper.make_node("Constant", [], [f"{name}_default"], value=numpy_helper.from_array(defaults[name], f"{name}_default"))],
            f"{name}_default", [], [helper.make_tensor_value_info(f"{name}_default", onnx_lib.TensorProto.FLOAT, None)])
        added += [helper.make_node("OptionalHasElement", [name], [f"{name}_given"]),
                  helper.make_node("If", [f"{name}_given"], [value], then_branch=fed, else_branch=default)]
        graph_input.type.CopyFrom(helper.make_optional_type_proto(graph_input.type))
    nodes = added + list(graph.node)  # before every reader: nodes stay in topological order
    graph.ClearField("node")
    graph.node.extend(nodes)
    return model


def optional_names(model: onnx_lib.ModelProto) -> list:
    """Names of ``model``'s optional inputs, in input order.

    Examples:
        >>> optional_names(onnx_lib.ModelProto())
        []
    """
    return [graph_input.name for graph_input in model.graph.input if graph_input.type.HasField("optional_type")]


def plain_inputs(model: onnx_lib.ModelProto) -> tuple:
    """``(model, {name: default})``: a copy of ``model`` with its optional inputs (:func:`with_defaults`) as plain
    tensor inputs, which every call must feed, and their defaults (see the module example)."""
    model = copy.deepcopy(model)
    graph = model.graph
    names = set(optional_names(model))
    checks = {node.output[0]: node.input[0] for node in graph.node if node.op_type == "OptionalHasElement" and node.input[0] in names}
    defaults, kept = {}, []
    for node in graph.node:
        if node.output[0] in checks:
            continue
        if node.op_type == "If" and node.input[0] in checks:
            name = checks[node.input[0]]
            constant, = helper.get_attribute_value(next(a for a in node.attribute if a.name == "else_branch")).node
            defaults[name] = numpy_helper.to_array(constant.attribute[0].t).copy()  # OpenVINO shares the memory it is fed: writable
            kept.append(helper.make_node("Identity", [name], list(node.output)))
        else:
            kept.append(node)
    graph.ClearField("node")
    graph.node.extend(kept)
    for graph_input in graph.input:
        if graph_input.name in names:
            graph_input.type.CopyFrom(graph_input.type.optional_type.elem_type)
    return model, defaults
