"""Running exported files on onnxruntime and OpenVINO: verification against PyTorch, node count and latency.

Both runtimes are tested on every exported model (``tests/test_openvino.py``). OpenVINO's CPU plugin
computes in bfloat16 by default where the processor has it (``precision=None`` here); pass
``precision="f32"`` (OpenVINO's ``{"INFERENCE_PRECISION_HINT": "f32"}``) to match PyTorch's float32.

Examples:
    >>> import tempfile, torch, torchgrade as tg
    >>> tone = tg.ToneMap("neutral")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = tg.onnx.export(tone, folder + "/tone.onnx")
    ...     verify(tone, path, torch.rand(1, 3, 8, 8) * 4) < 1e-4
    True
"""

from __future__ import annotations

import statistics
import time
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np
import onnx as onnx_lib  # the onnx package (absolute import), not this package
import torch
from torch import nn

from .graph import encode_output, frame_of, grade_feeds, grade_of, has_state

__all__ = ["RUNTIMES", "DEVICES", "Inputs", "OpenVINOSession", "session", "feeds", "reference", "verify", "metadata", "graph_nodes", "node_count",
           "latency_ms"]

RUNTIMES = ("onnxruntime", "openvino")
"""Inference runtimes :func:`session` opens a file on (both on the CPU)."""

Inputs = Union[torch.Tensor, Sequence[torch.Tensor]]


class _Port(NamedTuple):
    name: str
    type: str


class OpenVINOSession:
    """An OpenVINO compiled model behind onnxruntime's ``get_inputs()`` / ``run(None, feeds)`` calls.

    Inputs that have a default in the file (an initializer) are listed by neither runtime's
    ``get_inputs()``: feeding them is optional.

    Examples:
        >>> import tempfile, torch, torchgrade as tg
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     path = tg.onnx.export(tg.ToneMap("reinhard"), folder + "/tone.onnx")
        ...     [port.name for port in OpenVINOSession(path, "f32").get_inputs()]
        ['image']
    """

    def __init__(self, path, precision: Optional[str] = None, threads: Optional[int] = None):
        import openvino

        config = {} if precision is None else {"INFERENCE_PRECISION_HINT": precision}
        if threads is not None:
            config["INFERENCE_NUM_THREADS"] = threads
        defaults = {init.name for init in onnx_lib.load(str(path), load_external_data=False).graph.initializer}
        self.model = openvino.Core().compile_model(str(path), "CPU", config)
        # OpenVINO reads an input that has an initializer as a constant: a default there cannot be overridden.
        self.ports = [port for port in self.model.inputs if port.get_any_name() not in defaults]

    def get_inputs(self) -> list:
        types = {"f16": "tensor(float16)", "f32": "tensor(float)"}
        return [_Port(port.get_any_name(), types.get(port.get_element_type().get_type_name(), "")) for port in self.ports]

    def run(self, names, feeds: dict) -> list:
        results = self.model(feeds)
        return [results[port] for port in self.model.outputs]


DEVICES = {"cpu": "CPUExecutionProvider", "cuda": "CUDAExecutionProvider"}
"""Devices :func:`session` runs onnxruntime on, and the execution provider of each (OpenVINO: CPU only)."""


def session(path, runtime: str = "onnxruntime", precision: Optional[str] = None, device: str = "cpu", spin: bool = True,
            threads: Optional[int] = None):
    """A session on ``runtime`` (see :data:`RUNTIMES`) on ``device`` (see :data:`DEVICES`); ``precision``
    is OpenVINO's hint; ``threads`` the CPU threads one call may use (None: the runtime's default, one per core).
    A device whose provider this onnxruntime lacks is an error, not a quiet fall-back to the CPU.

    ``spin=False`` stops onnxruntime's worker threads spinning between tasks
    (``session.intra_op.allow_spinning``): where other processes share the cores, spinning threads wait on
    each other's time slices; on cores of its own spinning saves the wake-up (``benchmarks/results/onnx.md``
    has both on the same frames).

    Examples:
        >>> session("never.onnx", "tensorrt")
        Traceback (most recent call last):
        ...
        ValueError: runtime must be one of ('onnxruntime', 'openvino'), got 'tensorrt'
    """
    if runtime not in RUNTIMES:
        raise ValueError(f"runtime must be one of {RUNTIMES}, got {runtime!r}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive int or None, got {threads!r}")
    if device not in DEVICES or (runtime == "openvino" and device != "cpu"):
        raise ValueError(f"{runtime} runs here on {'cpu' if runtime == 'openvino' else tuple(DEVICES)}, got device {device!r}")
    if runtime == "openvino":
        return OpenVINOSession(path, precision, threads)
    import onnxruntime

    if DEVICES[device] not in onnxruntime.get_available_providers():
        raise ValueError(f"this onnxruntime has no {DEVICES[device]} (it has {', '.join(onnxruntime.get_available_providers())})")
    options = onnxruntime.SessionOptions()
    options.log_severity_level = 3  # inputs with defaults are optional by design: no warning per control
    options.add_session_config_entry("session.intra_op.allow_spinning", "1" if spin else "0")
    if threads is not None:
        options.intra_op_num_threads = threads
    return onnxruntime.InferenceSession(str(path), options, providers=[DEVICES[device]])


def feeds(runner, module: Optional[nn.Module], inputs: Inputs) -> dict:
    """Name the ``inputs`` for ``runner``'s graph; grading-control inputs not given take ``module``'s grade.

    Examples:
        >>> callable(feeds)
        True
    """
    inputs = (inputs,) if isinstance(inputs, torch.Tensor) else tuple(inputs)
    ports = runner.get_inputs()
    names = [i.name for i in ports]
    given = dict(zip(names, inputs))
    missing = [name for name in names if name not in given]
    if missing:
        controls = grade_feeds(grade_of(module), inputs[0].shape[0])
        given.update({name: controls[name] for name in missing})
    named = {name: value.detach().float().cpu().numpy() for name, value in given.items()}
    if ports[0].type == "tensor(float16)":
        named["image"] = named["image"].astype(np.float16)
    return named


def reference(module: nn.Module, inputs: Inputs) -> tuple:
    """PyTorch's outputs for ``inputs`` as the exported graph takes them (stateless for exposure).

    Examples:
        >>> import torchgrade as tg
        >>> len(reference(tg.AutoExposure(), (torch.ones(1, 3, 4, 4), torch.zeros(1), torch.tensor(0.0))))
        2
    """
    inputs = (inputs,) if isinstance(inputs, torch.Tensor) else tuple(inputs)
    with torch.no_grad():
        if has_state(module):
            return tuple(frame_of(module)(*inputs[:3]))
        return (module(inputs[0]),)


def verify(module: nn.Module, path, inputs: Inputs, runtime: str = "onnxruntime", precision: Optional[str] = None) -> float:
    """Run the ONNX file on ``runtime`` (CPU) and return the max abs difference from PyTorch.

    ``inputs`` is the image, or ``(image, adapted, dt)`` for a model with exposure; grading
    controls of a ``grade_inputs`` model take their defaults. PyTorch's output is encoded as the file's
    ``torchgrade.output`` says (an ``srgb8`` model's error is in 8-bit codes). See the module example.
    """
    runner = session(path, runtime, precision)
    outputs = runner.run(None, feeds(runner, module, inputs))
    image, *state = reference(module, inputs)
    expected = (encode_output(image, metadata(path).get("torchgrade.output", "linear")), *state)
    return max(float(np.max(np.abs(out.astype(np.float64) - exp.double().numpy()))) for out, exp in zip(outputs, expected))


def metadata(path) -> dict:
    """An ONNX file's ``metadata_props`` as a dict (see :mod:`~torchgrade.onnx.describe`).

    Examples:
        >>> callable(metadata)
        True
    """
    return {prop.key: prop.value for prop in onnx_lib.load(str(path), load_external_data=False).metadata_props}


def graph_nodes(graph: onnx_lib.GraphProto) -> list:
    """Every node of an ONNX graph, those of its subgraphs (a ``Scan``'s body) included, each before its subgraphs' nodes.

    Examples:
        >>> from onnx import helper
        >>> body = helper.make_graph([helper.make_node("Relu", ["x"], ["y"])], "body", [], [])
        >>> graph = helper.make_graph([helper.make_node("Scan", ["a"], ["b"], body=body, num_scan_inputs=1)], "g", [], [])
        >>> [node.op_type for node in graph_nodes(graph)]
        ['Scan', 'Relu']
    """
    nodes = []
    for node in graph.node:
        nodes.append(node)
        for attribute in node.attribute:
            if attribute.type == onnx_lib.AttributeProto.GRAPH:
                nodes += graph_nodes(attribute.g)
    return nodes


def node_count(path) -> int:
    """Number of nodes in an ONNX file, those of subgraphs included (:func:`graph_nodes`).

    Examples:
        >>> callable(node_count)
        True
    """
    return len(graph_nodes(onnx_lib.load(str(path), load_external_data=False).graph))


def latency_ms(path, inputs: Inputs, module: Optional[nn.Module] = None, repeats: int = 5, runtime: str = "onnxruntime",
               precision: Optional[str] = None) -> float:
    """Median wall time (ms) of ``repeats`` runs on ``runtime`` on ``inputs``, after one warm-up run.

    The one timing loop of the package: the CLI and ``python -m export`` report this number.

    Examples:
        >>> callable(latency_ms)
        True
    """
    runner = session(path, runtime, precision)
    named = feeds(runner, module, inputs)
    runner.run(None, named)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        runner.run(None, named)
        times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times)
