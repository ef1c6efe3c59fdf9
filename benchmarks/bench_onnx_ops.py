"""What single ONNX operators cost on onnxruntime's CPU, relative to a ``Mul`` by a number: the figures behind the
export forms (:mod:`torchgrade.onnx`), which trade ``Where``, comparisons, ``Sign``, ``Pow`` and reductions over the
3 channels for arithmetic.

    .venv/bin/python -m benchmarks onnx_ops

Each operator (or short pattern) is repeated 20 times in a chain on a strip of 3 x 68 x 1920 float32 values (about
2^17 pixels, the strips a look's per-pixel end runs on), in one onnxruntime session on one intra-op thread; the
patterns of a round alternate (:func:`benchmarks.common.median_ms`). Reported per pattern: ms for a 1920x1080 frame
(16 strips) and that over the ``Mul``'s. Writes onnx_ops.json and onnx_ops.md to ``--out`` (default benchmarks/out;
the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import onnxruntime
from onnx import TensorProto, helper, numpy_helper

from benchmarks.common import argument_parser, median_ms, write_results

ROOT = Path(__file__).resolve().parents[1]

COMMAND = ".venv/bin/python -m benchmarks onnx_ops"
STRIP = (1, 3, 68, 1920)
STRIPS_PER_FRAME = 16
CHAIN, REPEATS = 20, 9


def _constants() -> list:
    numbers = {"half": 0.5, "two": 2.0, "low": -65504.0, "high": 65504.0, "zero": 0.0}
    tensors = [numpy_helper.from_array(np.array(v, np.float32), name) for name, v in numbers.items()]
    tensors.append(numpy_helper.from_array(np.full((1, 3, 1, 1), 0.3, np.float32), "per_channel"))
    tensors.append(numpy_helper.from_array(np.full((3, 3), 0.3, np.float32), "matrix"))
    tensors += [numpy_helper.from_array(np.array(v, np.int64), name) for name, v in
                {"channel_axis": [1], "first": [0], "second": [1], "flat": [1, 3, -1], "strip": list(STRIP)}.items()]
    return tensors


def _one(op: str, *inputs: str, **attributes):
    """A step of one node: ``x -> op(x, *inputs)``."""
    return lambda x, out: [helper.make_node(op, [x, *inputs], [out], **attributes)]


def _guarded(op: str, *inputs: str):
    """A step whose input is first made non-negative (``Abs``), for operators undefined below 0."""
    return lambda x, out: [helper.make_node("Abs", [x], [out + "_abs"]), helper.make_node(op, [out + "_abs", *inputs], [out])]


def _less_where(x, out):
    return [helper.make_node("Less", [x, "half"], [out + "_c"]), helper.make_node("Where", [out + "_c", "half", x], [out])]


def _nan_where(x, out):
    return [helper.make_node("IsNaN", [x], [out + "_c"]), helper.make_node("Where", [out + "_c", "zero", x], [out])]


def _where_of_frames(x, out):
    return [helper.make_node("Less", [x, "half"], [out + "_c"]), helper.make_node("Mul", [x, "two"], [out + "_d"]),
            helper.make_node("Where", [out + "_c", x, out + "_d"], [out])]


def _less_cast(x, out):
    return [helper.make_node("Less", [x, "half"], [out + "_c"]), helper.make_node("Cast", [out + "_c"], [out + "_f"], to=1),
            helper.make_node("Add", [x, out + "_f"], [out])]


def _channel_reduction(op: str):
    return lambda x, out: [helper.make_node(op, [x, "channel_axis"] if op == "ReduceSum" else [x], [out + "_r"], keepdims=1,
                                            **({} if op == "ReduceSum" else {"axes": [1]})),
                           helper.make_node("Add", [x, out + "_r"], [out])]


def _plane_products(x, out):
    """A 3x3 matrix as torchgrade exports it: a plane of each input channel times a column, summed."""
    nodes = []
    for j in range(3):
        start, end = ("first", "second") if j == 0 else (f"c{j}", f"c{j + 1}")
        nodes.append(helper.make_node("Slice", [x, start, end, "channel_axis"], [f"{out}_s{j}"]))
        nodes.append(helper.make_node("Mul", [f"{out}_s{j}", "per_channel"], [f"{out}_m{j}"]))
    nodes.append(helper.make_node("Add", [f"{out}_m0", f"{out}_m1"], [f"{out}_a"]))
    nodes.append(helper.make_node("Add", [f"{out}_a", f"{out}_m2"], [out]))
    return nodes


def _matmul(x, out):
    return [helper.make_node("Reshape", [x, "flat"], [out + "_f"]), helper.make_node("MatMul", ["matrix", out + "_f"], [out + "_m"]),
            helper.make_node("Reshape", [out + "_m", "strip"], [out])]


def _einsum(x, out):
    return [helper.make_node("Einsum", ["matrix", x], [out], equation="ij,njhw->nihw")]


def _split_concat(x, out):
    planes = [f"{out}_{c}" for c in "rgb"]
    return [helper.make_node("Split", [x], planes, axis=1), helper.make_node("Concat", planes[::-1], [out], axis=1)]


PATTERNS = {
    "Mul by a number": _one("Mul", "half"),
    "Add of two frames": lambda x, out: [helper.make_node("Add", [x, x], [out])],
    "Clip": _one("Clip", "low", "high"),
    "Max with a number": _one("Max", "half"),
    "Mul by a colour (1, 3, 1, 1)": _one("Mul", "per_channel"),
    "Exp": lambda x, out: [helper.make_node("Clip", [x, "zero", "half"], [out + "_c"]), helper.make_node("Exp", [out + "_c"], [out])],
    "Sqrt": _guarded("Sqrt"),
    "Log": _guarded("Log"),
    "Pow by a number": _guarded("Pow", "half"),
    "Atan": _one("Atan"),
    "Sign": _one("Sign"),
    "Less, Cast to float": _less_cast,
    "Less, Where(c, number, x)": _less_where,
    "IsNaN, Where(c, 0, x)": _nan_where,
    "Where of two frames": _where_of_frames,
    "ReduceSum over channels": _channel_reduction("ReduceSum"),
    "ReduceMax over channels": _channel_reduction("ReduceMax"),
    "3x3 matrix, plane products": _plane_products,
    "3x3 matrix, MatMul": _matmul,
    "3x3 matrix, Einsum": _einsum,
    "Split and Concat": _split_concat,
}
"""Each pattern as ``step(x, out) -> nodes`` computing ``out`` from ``x``; its cost is its nodes' together."""


def chain_session(step) -> onnxruntime.InferenceSession:
    """``CHAIN`` steps in a row, one intra-op thread."""
    nodes, x = [], "x"
    for k in range(CHAIN):
        nodes += step(x, f"s{k}")
        x = f"s{k}"
    nodes.append(helper.make_node("Identity", [x], ["y"]))
    constants = _constants() + [numpy_helper.from_array(np.array([j], np.int64), f"c{j}") for j in (1, 2, 3)]
    graph = helper.make_graph(nodes, "chain", [helper.make_tensor_value_info("x", TensorProto.FLOAT, STRIP)],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)], constants)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.log_severity_level = 3
    return onnxruntime.InferenceSession(model.SerializeToString(), options, providers=["CPUExecutionProvider"])


def measure() -> dict:
    """``{pattern: {"frame_ms": ms per 1080p frame, "over_mul": that / the Mul's}}``."""
    strip = np.random.default_rng(0).random(STRIP, dtype=np.float32) * 4.0 - 1.0
    sessions = {name: chain_session(step) for name, step in PATTERNS.items()}
    calls = {name: (lambda s=session: s.run(None, {"x": strip})) for name, session in sessions.items()}
    medians = median_ms(calls, REPEATS)
    frame = {name: ms / CHAIN * STRIPS_PER_FRAME for name, ms in medians.items()}
    mul = frame["Mul by a number"]
    return {name: {"frame_ms": round(ms, 2), "over_mul": round(ms / mul, 1)} for name, ms in frame.items()}


def main(argv=None) -> int:
    args = argument_parser(__doc__).parse_args(argv)
    load = os.getloadavg()[0]
    rows = measure()
    report = {"command": COMMAND, "onnxruntime": onnxruntime.__version__, "strip": STRIP, "chain": CHAIN, "repeats": REPEATS,
              "load_average": [load, os.getloadavg()[0]], "results": rows}
    lines = ["# onnxruntime CPU: single operators on strips of 2^17 pixels, one thread", "",
             f"`{COMMAND}` (onnxruntime {onnxruntime.__version__}; each pattern {CHAIN} times in a chain on a "
             f"{'x'.join(map(str, STRIP))} float32 strip, median of {REPEATS} alternating rounds; load average "
             f"{report['load_average'][0]:.1f} at the start, {report['load_average'][1]:.1f} at the end)", "",
             "| pattern | ms per 1920x1080 frame | over a Mul by a number |", "| --- | ---: | ---: |"]
    lines += [f"| {name} | {r['frame_ms']} | {r['over_mul']} |" for name, r in rows.items()]
    write_results(args.out, "onnx_ops", report, lines, COMMAND)
    return 0


if __name__ == "__main__":
    sys.exit(main())
