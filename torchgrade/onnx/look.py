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

from ..look.postfx import PostFX
from .exporter import export
from .frames import CODE_MAX, read_frame_format
from .graph import has_state
from .verify import latency_ms, metadata, node_count, verify

__all__ = ["RUNS", "graph_inputs", "export_look"]

RUNS = {"openvino default": ("openvino", None), "openvino f32": ("openvino", "f32"), "onnxruntime": ("onnxruntime", None)}
"""The runtimes and precisions :func:`export_look` reports: ``{label: (runtime, OpenVINO precision hint)}``."""


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


def export_look(look: PostFX, path, images: Mapping[str, torch.Tensor], lut_backend: str = "slices",
                grade_inputs: bool = False, output: str = "linear", strips: bool = True, **frames) -> list:
    """Export ``look`` to ``path`` and report it: one line with its stages, input and output formats and node count,
    for a look baked by :meth:`~torchgrade.PostFX.to_lut` one line with the LUT's error report
    (:class:`~torchgrade.lut.ErrorReport`),
    one line per image of ``images`` (``{name: (1, 3, H, W)}``) with the max abs error against PyTorch on
    each runtime of :data:`~torchgrade.onnx.RUNTIMES` (OpenVINO at float32 and at its default precision;
    in 8-bit codes for an integer output, ``srgb8`` or ``srgb16``), one line with the median latency of each runtime on the
    first image. ``strips`` and ``frames`` (``io_dtype``, ``input_dtype``, ``layout``, ``output_layout``,
    ``optional_inputs``) are :func:`~torchgrade.onnx.export`'s.

    See the module example.
    """
    export(look, path, lut_backend=lut_backend, grade_inputs=grade_inputs, output=output, strips=strips, **frames)
    fmt = read_frame_format(metadata(path))
    formats = f"input {str(fmt.input_dtype).replace('torch.', '')} {fmt.layout}, output {output} {fmt.output_layout}"
    lines = [f"{path}: stages {' -> '.join(look.stages())}, {formats}, {node_count(path)} nodes"]
    report = getattr(getattr(look, "lut", None), "error_report", None)
    if report is not None:
        lines.append(f"  baked LUT vs the look it replaces: {report}")
    codes = fmt.output_dtype in CODE_MAX
    for name, image in images.items():
        errors = [f"{label} {verify(look, path, graph_inputs(look, image), runtime, precision, codes=codes):.2e}"
                  for label, (runtime, precision) in RUNS.items()]
        lines.append(f"  {name} {tuple(image.shape[-2:])}: max abs error vs PyTorch: {', '.join(errors)}")
    name, image = next(iter(images.items()))
    latencies = [f"{label} {latency_ms(path, graph_inputs(look, image), look, runtime=runtime, precision=precision):.1f} ms"
                 for label, (runtime, precision) in RUNS.items()]
    lines.append(f"  latency on {name}: {', '.join(latencies)} (median of 5)")
    return lines
