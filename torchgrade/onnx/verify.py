"""Running exported files on onnxruntime: verification against PyTorch, node count and latency.

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
from typing import Optional, Sequence, Union

import numpy as np
import onnx as onnx_lib  # the onnx package (absolute import), not this package
import torch
from torch import nn

from .graph import frame_of, grade_feeds, grade_of, has_state

__all__ = ["Inputs", "session", "feeds", "reference", "verify", "node_count", "latency_ms"]

Inputs = Union[torch.Tensor, Sequence[torch.Tensor]]


def session(path):
    """An onnxruntime session on the CPU provider.

    Examples:
        >>> callable(session)
        True
    """
    import onnxruntime

    return onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def feeds(runner, module: Optional[nn.Module], inputs: Inputs) -> dict:
    """Name the ``inputs`` for ``runner``'s graph; grading-control inputs not given take ``module``'s grade.

    Examples:
        >>> callable(feeds)
        True
    """
    inputs = (inputs,) if isinstance(inputs, torch.Tensor) else tuple(inputs)
    names = [i.name for i in runner.get_inputs()]
    given = dict(zip(names, inputs))
    missing = [name for name in names if name not in given]
    if missing:
        controls = grade_feeds(grade_of(module), inputs[0].shape[0])
        given.update({name: controls[name] for name in missing})
    return {name: value.detach().float().numpy() for name, value in given.items()}


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


def verify(module: nn.Module, path, inputs: Inputs) -> float:
    """Run the ONNX file on onnxruntime (CPU) and return the max abs difference from PyTorch.

    ``inputs`` is the image, or ``(image, adapted, dt)`` for a model with exposure; grading
    controls of a ``grade_inputs`` model default to ``module``'s grade. See the module example.
    """
    runner = session(path)
    outputs = runner.run(None, feeds(runner, module, inputs))
    expected = reference(module, inputs)
    return max(float(np.max(np.abs(out - exp.float().numpy()))) for out, exp in zip(outputs, expected))


def node_count(path) -> int:
    """Number of nodes in an ONNX file's main graph.

    Examples:
        >>> callable(node_count)
        True
    """
    return len(onnx_lib.load(str(path), load_external_data=False).graph.node)


def latency_ms(path, inputs: Inputs, module: Optional[nn.Module] = None, repeats: int = 5) -> float:
    """Median wall time (ms) of ``repeats`` onnxruntime runs on ``inputs``, after one warm-up run.

    The one timing loop of the package: the CLI and ``python -m export`` report this number.

    Examples:
        >>> callable(latency_ms)
        True
    """
    runner = session(path)
    named = feeds(runner, module, inputs)
    runner.run(None, named)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        runner.run(None, named)
        times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times)
