"""A look exported, verified and timed in one call: what ``torchgrade export`` and ``python -m export`` run.

Examples:
    >>> import tempfile, torch, torchgrade as tg
    >>> look = tg.PostFX(grade={"contrast": 10}, tonemap="neutral")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     lines = export_look(look, folder + "/look.onnx", {"noise": torch.rand(1, 3, 16, 16)})
    >>> len(lines)
    3
"""

from __future__ import annotations

from typing import Mapping

import torch

from ..pipeline import PostFX
from .exporter import export
from .graph import has_state
from .verify import latency_ms, node_count, verify

__all__ = ["graph_inputs", "export_look"]


def graph_inputs(look: PostFX, image: torch.Tensor):
    """The image, plus a starting adaptation state and dt = 0 when the look carries state between frames.

    Examples:
        >>> import torchgrade as tg
        >>> len(graph_inputs(tg.PostFX(exposure={}), torch.ones(2, 3, 4, 4)))
        3
    """
    if not has_state(look):
        return image
    return image, torch.zeros(image.shape[0]), torch.tensor(0.0)


def export_look(look: PostFX, path, images: Mapping[str, torch.Tensor], lut_backend: str = "strip",
                grade_inputs: bool = False) -> list:
    """Export ``look`` to ``path`` and report it: one line with its stages and node count, one line per
    image of ``images`` (``{name: (1, 3, H, W)}``) with the max abs error against PyTorch, one line
    with the median onnxruntime latency on the first image.

    See the module example.
    """
    export(look, path, lut_backend=lut_backend, grade_inputs=grade_inputs)
    lines = [f"{path}: stages {' -> '.join(look.stages())}, {node_count(path)} nodes"]
    for name, image in images.items():
        error = verify(look, path, graph_inputs(look, image))
        lines.append(f"  {name} {tuple(image.shape[-2:])}: max abs error vs PyTorch {error:.2e}")
    name, image = next(iter(images.items()))
    latency = latency_ms(path, graph_inputs(look, image), look)
    lines.append(f"  onnxruntime latency on {name}: {latency:.1f} ms (median of 5)")
    return lines
