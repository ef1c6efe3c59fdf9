"""Running exported files on onnxruntime and OpenVINO: verification against PyTorch, node count and latency.

Both runtimes are tested on every exported model (``tests/onnx/test_openvino.py``). OpenVINO's CPU plugin
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
from pathlib import Path
from types import SimpleNamespace
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np
import onnx as onnx_lib  # the onnx package (absolute import), not this package
import torch
from torch import nn

from .defaults import STATE_DEFAULTS, plain_inputs
from .describe import CONFIG_KEY, FORMER_CONFIG_KEY
from .frames import check_batch, decode_frame, eight_bit_codes, encode_frame, from_nchw, model_input, read_frame_format, to_nchw
from .graph import GRADE_INPUTS, frame_of, grade_feeds, grade_of, has_state

__all__ = ["RUNTIMES", "DEVICES", "Inputs", "OpenVINOSession", "session", "feeds", "reference", "verify", "metadata", "graph_nodes", "node_count",
           "latency_ms"]

RUNTIMES = ("onnxruntime", "openvino")
"""Inference runtimes :func:`session` opens a file on (both on the CPU)."""

Inputs = Union[torch.Tensor, Sequence[torch.Tensor]]


class _Port(NamedTuple):
    name: str
    type: str


class OpenVINOSession:
    """An OpenVINO compiled model behind onnxruntime's ``get_inputs()`` / ``get_modelmeta()`` / ``run(None, feeds)`` calls.

    OpenVINO reads no ONNX optional type: the file is compiled in its plain-input form
    (:func:`~torchgrade.onnx.defaults.plain_inputs`) and an optional input not fed gets its default here, so
    feeding is optional on both runtimes, and ``get_inputs()`` lists optional inputs as onnxruntime does.

    Examples:
        >>> import tempfile, torch, torchgrade as tg
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     path = tg.onnx.export(tg.PostFX(exposure={}), folder + "/look.onnx")
        ...     [(port.name, port.type) for port in OpenVINOSession(path, "f32").get_inputs()]
        [('image', 'tensor(float)'), ('adapted', 'optional(tensor(float))'), ('dt', 'optional(tensor(float))')]
    """

    def __init__(self, path, precision: Optional[str] = None, threads: Optional[int] = None):
        import openvino

        config: dict[str, str | int] = {} if precision is None else {"INFERENCE_PRECISION_HINT": precision}
        if threads is not None:
            config["INFERENCE_NUM_THREADS"] = threads
        model = onnx_lib.load(str(path))
        self.meta = SimpleNamespace(custom_metadata_map={prop.key: prop.value for prop in model.metadata_props})
        plain, self.defaults = plain_inputs(model)
        core = openvino.Core()
        self.model = core.compile_model(core.read_model(plain.SerializeToString(), b""), "CPU", config)

    def get_inputs(self) -> list:
        types = {"f16": "float16", "f32": "float", "u8": "uint8", "u16": "uint16"}
        ports = []
        for port in self.model.inputs:
            name, element = port.get_any_name(), f"tensor({types.get(port.get_element_type().get_type_name(), '')})"
            ports.append(_Port(name, f"optional({element})" if name in self.defaults else element))
        return ports

    def get_modelmeta(self):
        return self.meta

    def run(self, names, feeds: dict) -> list:
        results = self.model({**{name: value for name, value in self.defaults.items() if name not in feeds}, **feeds})
        return [results[port] for port in self.model.outputs]


DEVICES = {"cpu": "CPUExecutionProvider", "cuda": "CUDAExecutionProvider"}
"""Devices :func:`session` runs onnxruntime on, and the execution provider of each (OpenVINO: CPU only)."""


def session(path, runtime: str = "onnxruntime", precision: Optional[str] = None, device: str = "cpu", spin: bool = True,
            threads: Optional[int] = None):
    """A session on ``runtime`` (see :data:`RUNTIMES`) on ``device`` (see :data:`DEVICES`; ``"cuda:1"`` picks a GPU);
    ``precision`` is OpenVINO's hint; ``threads`` the CPU threads one call may use (None: the runtime's default, one per core).
    A device whose provider this onnxruntime lacks, or could not start (onnxruntime-gpu without the CUDA and cuDNN
    libraries it needs logs an error and runs on the CPU), is an error, not a quiet CPU run; nodes the CUDA provider
    has no kernel for run on the CPU provider, as onnxruntime places them.

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
    if not Path(path).is_file():
        raise ValueError(f"no ONNX file at {str(path)!r}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive int or None, got {threads!r}")
    kind, numbered, index = str(device).partition(":")
    if kind not in DEVICES or (runtime == "openvino" and device != "cpu") or (numbered and (kind != "cuda" or not index.isdigit())):
        raise ValueError(f"{runtime} runs here on {'cpu' if runtime == 'openvino' else ('cpu', 'cuda', 'cuda:N')}, got device {device!r}")
    if runtime == "openvino":
        return OpenVINOSession(path, precision, threads)
    import onnxruntime

    provider = DEVICES[kind]
    if provider not in onnxruntime.get_available_providers():
        raise ValueError(f"this onnxruntime has no {provider} (it has {', '.join(onnxruntime.get_available_providers())})")
    options = onnxruntime.SessionOptions()
    options.add_session_config_entry("session.intra_op.allow_spinning", "1" if spin else "0")
    if threads is not None:
        options.intra_op_num_threads = threads
    providers = [(provider, {"device_id": int(index or 0)}), "CPUExecutionProvider"] if kind == "cuda" else [provider]
    try:
        runner = onnxruntime.InferenceSession(str(path), options, providers=providers)
    except _unreadable() as error:
        raise ValueError(f"{str(path)!r} is not an ONNX model onnxruntime can load: {error}") from None
    if runner.get_providers()[0] != provider:
        raise ValueError(f"onnxruntime could not start {provider} (it runs on {', '.join(runner.get_providers())}): "
                         "are the CUDA and cuDNN libraries that this onnxruntime-gpu needs installed and found?")
    return runner


def _unreadable() -> tuple:
    """onnxruntime's errors for a file that is no model it can load (they derive from ``Exception`` alone)."""
    from onnxruntime.capi import onnxruntime_pybind11_state as state

    return state.InvalidProtobuf, state.InvalidGraph, state.NoModel, state.Fail


def _inputs(inputs: Inputs, stateful: bool) -> tuple:
    """``inputs`` as a tuple ``(image[, adapted, dt])``, checked: the image as the look takes it, state only for a
    look with eye adaptation."""
    inputs = (inputs,) if isinstance(inputs, torch.Tensor) else tuple(inputs)
    if len(inputs) not in ((1, 3) if stateful else (1,)):
        takes = "(image,) or (image, adapted, dt)" if stateful else "the image alone (it has no eye adaptation)"
        raise ValueError(f"the look takes {takes}; got {len(inputs)} inputs")
    image = check_batch(inputs[0])
    if len(inputs) == 3:
        try:
            adapted, dt = (torch.as_tensor(value, dtype=torch.float32) for value in inputs[1:])
        except (TypeError, ValueError, RuntimeError):
            raise ValueError(f"adapted and dt must be numbers or tensors, got {type(inputs[1]).__name__} and {type(inputs[2]).__name__}") from None
        if adapted.shape != image.shape[:1] or dt.dim() != 0:
            raise ValueError(f"adapted must have shape ({image.shape[0]},) (one value per image) and dt be a scalar, "
                             f"got shapes {tuple(adapted.shape)} and {tuple(dt.shape)}")
        inputs = (image, adapted, dt)
    return inputs


def feeds(runner, module: Optional[nn.Module], inputs: Inputs) -> dict:
    """Name the ``inputs`` for ``runner``'s graph: the image as the look takes it (float ``(batch, 3, height, width)``),
    converted to the file's frame format (:func:`~torchgrade.onnx.frames.model_input`), then ``adapted`` and ``dt``
    where given. Inputs not given are left to their defaults where optional; plain ones get a still's state
    (:data:`~torchgrade.onnx.defaults.STATE_DEFAULTS`) and ``module``'s grade.

    Examples:
        >>> callable(feeds)
        True
    """
    ports = runner.get_inputs()
    stateful = any(port.name == "adapted" for port in ports)
    if module is not None and has_state(module) != stateful:
        mismatch = ("the file takes adapted and dt (a look with eye adaptation) but the module has no exposure stage" if stateful
                    else "the module has an exposure stage but the file takes no adapted and dt")
        raise ValueError(f"{mismatch}: pass the module the file was exported from")
    image, *state = _inputs(inputs, stateful)
    frames = read_frame_format(runner.get_modelmeta().custom_metadata_map)
    named = {"image": model_input(image, frames).numpy(), **dict(zip(("adapted", "dt"), (value.numpy() for value in state)))}
    required = [port.name for port in ports if port.name not in named and not port.type.startswith("optional")]
    controls = grade_feeds(grade_of(module), image.shape[0]) if set(required) & set(GRADE_INPUTS) else {}
    for name in required:
        if name in STATE_DEFAULTS:  # one value per image: onnxruntime plans buffers by the batch the image names
            default = STATE_DEFAULTS[name]
            named[name] = np.broadcast_to(default, image.shape[:1] if default.ndim else ()).copy()
        else:
            named[name] = controls[name].numpy()
    return named


def reference(module: nn.Module, inputs: Inputs) -> tuple:
    """PyTorch's outputs for ``inputs`` as the exported graph takes them (stateless for exposure; an image alone
    starts a sequence, as the graph's defaults do).

    Examples:
        >>> import torchgrade as tg
        >>> len(reference(tg.AutoExposure(), (torch.ones(1, 3, 4, 4), torch.zeros(1), torch.tensor(0.0))))
        2
        >>> reference(tg.ToneMap(), (torch.ones(1, 3, 4, 4), torch.zeros(1), torch.tensor(0.0)))
        Traceback (most recent call last):
        ...
        ValueError: the look takes the image alone (it has no eye adaptation); got 3 inputs
        >>> reference(tg.AutoExposure(), torch.ones(3, 4, 4))
        Traceback (most recent call last):
        ...
        ValueError: image must be a batch, (batch, 3, height, width), got (3, 4, 4)
    """
    stateful = has_state(module)
    image, *state = _inputs(inputs, stateful)
    with torch.no_grad():
        if stateful:
            adapted, dt = state or (torch.zeros(image.shape[0]), torch.tensor(0.0))
            frame = frame_of(module)
            assert frame is not None  # a module with state has its frame function
            return tuple(frame(image, adapted, dt))
        return (module(image),)


def verify(module: nn.Module, path, inputs: Inputs, runtime: str = "onnxruntime", precision: Optional[str] = None,
           codes: bool = False) -> float:
    """Run the ONNX file on ``runtime`` (CPU) and return the max abs difference from PyTorch.

    ``inputs`` is the image as the look takes it (float ``(batch, 3, height, width)``), or ``(image, adapted, dt)``
    for a look with eye adaptation (the image alone: a still). The file gets the image in its own frame format
    (:func:`~torchgrade.onnx.frames.model_input`: its layout and dtype, integer inputs as sRGB codes) and PyTorch
    runs the look on that same input, decoded; its output is encoded as the file's (an ``srgb8`` model's error is in
    8-bit codes). ``codes=True`` gives the image's error in 8-bit sRGB codes whatever the encoding
    (:func:`~torchgrade.onnx.frames.eight_bit_codes`). See the module example.
    """
    runner = session(path, runtime, precision)
    frames = read_frame_format(runner.get_modelmeta().custom_metadata_map)
    outputs = runner.run(None, feeds(runner, module, inputs))
    image, *state = _inputs(inputs, has_state(module))
    decoded = decode_frame(to_nchw(model_input(image, frames), frames.layout), frames.input_dtype)
    result, *expected_state = reference(module, (decoded, *state))
    expected = (from_nchw(encode_frame(result, frames.output, frames.float_dtype), frames.output_layout), *expected_state)
    errors = []
    for index, (out, exp) in enumerate(zip(outputs, expected)):
        out, exp = out.astype(np.float64), exp.double().numpy()
        if codes and index == 0:
            out, exp = eight_bit_codes(out, frames.output), eight_bit_codes(exp, frames.output)
        errors.append(float(np.max(np.abs(out - exp))))
    return max(errors)


def metadata(path) -> dict:
    """An ONNX file's ``metadata_props`` as a dict (see :mod:`~torchgrade.onnx.describe`); the config of a file written
    under the former key (:data:`~torchgrade.onnx.describe.FORMER_CONFIG_KEY`) is given under today's,
    ``"torchgrade.config"``.

    Examples:
        >>> callable(metadata)
        True
    """
    props = {prop.key: prop.value for prop in onnx_lib.load(str(path), load_external_data=False).metadata_props}
    if FORMER_CONFIG_KEY in props:
        props.setdefault(CONFIG_KEY, props.pop(FORMER_CONFIG_KEY))
    return props


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
