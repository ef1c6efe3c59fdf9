"""The export-ready form of a look: each stage's :meth:`~torchgrade.base.stage.Stage.export_form` in one graph.

The exporter asks, it does not look inside: a look (anything with a ``stages()`` method, as
:class:`~torchgrade.PostFX`) lists its stages; each stage gives its export form, and the export
options its ``export_form`` accepts by name (``backend`` for a LUT, whose interpolation is its own
control) are passed to it; a stage that keeps state between frames gives its stateless frame function.
Only ``grade_inputs`` is grade-specific: :class:`GradeWithInputs` turns a
:class:`~torchgrade.ColorGrade`'s number controls (:data:`GRADE_INPUTS`) into graph inputs.

Examples:
    >>> import torchgrade as tg
    >>> graph = export_graph(tg.ToneMap("neutral"))
    >>> input_names(graph), output_names(graph)
    (['image'], ['output'])
"""

from __future__ import annotations

import inspect
from typing import Callable, Optional, Sequence

import torch
from torch import nn

from ..grading.grade import graded_image
from ..grading.layer import ColorGrade
from ..lut.backends import backend_named
from .frames import (
    FrameFormat,
    decode_frame,
    encode_frame,
    from_nchw,
    to_nchw,
    trace_input,
)
from .strips import mark

__all__ = ["GRADE_INPUTS", "GradeWithInputs", "ExportGraph", "export_graph", "grade_feeds", "grade_of", "frame_of", "has_state", "is_per_pixel",
           "input_names", "output_names", "example_inputs", "default_example"]

GRADE_INPUTS = tuple(name for name, control in ColorGrade.controls.items() if control.kind == "number")
"""The :class:`~torchgrade.ColorGrade` controls a ``grade_inputs`` graph takes as inputs, in input order."""


def frame_of(stage: nn.Module) -> Optional[Callable]:
    """The stateless frame function ``(image, adapted, dt) -> (image, adapted)`` of a stage that keeps
    state between frames, or ``None`` for a stateless stage.

    It is the stage's own ``frame`` method (:meth:`~torchgrade.AutoExposure.frame`).

    Examples:
        >>> import torchgrade as tg
        >>> frame_of(tg.ToneMap()) is None, frame_of(tg.AutoExposure()) is None
        (True, False)
    """
    return getattr(stage, "frame", None)


class GradeWithInputs(nn.Module):
    """``ColorGrade`` whose controls are graph inputs: ``forward(image, *controls)`` in :data:`GRADE_INPUTS` order.

    Its curves (control points, not inputs) and the ``aces`` and ``log_space`` settings are baked into the
    graph. Each control is clamped to its range in :attr:`ColorGrade.controls <torchgrade.ColorGrade.controls>`:
    a graph cannot raise, and a served look should stay one that ``ColorGrade`` accepts (contrast 500 becomes 100).

    Examples:
        >>> import torch
        >>> feeds = grade_feeds(None, 1)
        >>> GradeWithInputs(False)(torch.ones(1, 3, 2, 2), *feeds.values()).shape
        torch.Size([1, 3, 2, 2])
    """

    per_pixel = True
    """Each output pixel depends on its input pixel alone (see :attr:`torchgrade.base.stage.Stage.per_pixel`)."""

    takes_nan_free = True
    """See :attr:`torchgrade.base.stage.Stage.takes_nan_free`."""

    def __init__(self, aces: bool, curves: Optional[dict] = None, log_space: str = "acescc"):
        super().__init__()
        self.aces = aces
        self.curves = curves or {}
        self.log_space = log_space

    def forward(self, image: torch.Tensor, *controls: torch.Tensor, nan_free: bool = False) -> torch.Tensor:
        clamped = {name: value.clamp(*ColorGrade.controls[name].range) for name, value in zip(GRADE_INPUTS, controls)}
        return graded_image(image, self.aces, self.log_space, nan_free=nan_free, planes=False, **clamped, **self.curves)


class ExportGraph(nn.Module):
    """The stages of a look as one graph: ``(image[, adapted, dt][, *controls]) -> output[, adapted]``.

    ``frames`` (:class:`~torchgrade.onnx.frames.FrameFormat`) says how the image comes in (layout, dtype; integer
    codes are decoded to linear) and how the output goes out (encoding, dtype, layout); the stages compute in float32.

    Examples:
        >>> import torchgrade as tg
        >>> graph = ExportGraph([tg.ToneMap()], frames=FrameFormat(torch.float16, output="srgb8"))
        >>> graph(torch.ones(1, 3, 2, 2, dtype=torch.float16)).dtype
        torch.uint8
    """

    def __init__(self, stages: Sequence[nn.Module], exposure: Optional[nn.Module] = None, frames: FrameFormat = FrameFormat(),
                 strips: bool = True):
        super().__init__()
        self.stages = nn.ModuleList(stages)
        self.exposure = exposure
        self.frames = frames
        self.strips = strips

    def forward(self, image: torch.Tensor, *extra: torch.Tensor):
        frames = self.frames
        start = _per_pixel_from(self.stages) if self.strips else len(self.stages)
        in_strips = start < len(self.stages)
        # A look per pixel from its input decodes the input in the strips too; onnxruntime's Pad, which cuts the
        # strips, has no uint16 kernel, so uint16 codes are cast first.
        from_input = in_strips and start == 0 and self.exposure is None
        frame = to_nchw(image.float() if frames.input_dtype == torch.uint16 else image, frames.layout)
        frame = decode_frame(mark(frame) if from_input else frame, frames.input_dtype)
        graded, *state = self._graded(frame, *extra, mark_at=None if from_input else start)
        encoded = encode_frame(graded, frames.output, frames.float_dtype)
        output = from_nchw(mark(encoded, end=True) if in_strips else encoded, frames.output_layout)
        return (output, *state) if state else output

    def _graded(self, image: torch.Tensor, *extra: torch.Tensor, mark_at: Optional[int] = None) -> tuple:
        if self.exposure is not None:
            adapted, dt, *controls = extra
            frame = frame_of(self.exposure)
            assert frame is not None  # the exposure stage keeps state (_look_stages)
            image, adapted = frame(image, adapted, dt)
        else:
            controls = list(extra)
        for index, stage in enumerate(self.stages):
            image = mark(image) if index == mark_at else image
            args = (image, *controls) if isinstance(stage, GradeWithInputs) else (image,)
            # the exposed frame holds no NaN (auto_exposure), so the stage after it skips its sanitize's NaN pass
            trusted = index == 0 and self.exposure is not None and getattr(stage, "takes_nan_free", False)
            image = stage(*args, nan_free=True) if trusted else stage(*args)
        return (image, adapted) if self.exposure is not None else (image,)


def is_per_pixel(module: nn.Module) -> bool:
    """Whether each output pixel of ``module`` depends on its input pixel alone: a stage that says so
    (:attr:`~torchgrade.base.stage.Stage.per_pixel`), or an ``nn.Sequential`` of such stages and identity stages.

    Examples:
        >>> import torchgrade as tg
        >>> is_per_pixel(nn.Sequential(tg.ColorGrade(contrast=10), tg.Bloom(intensity=0.0), tg.ToneMap())), is_per_pixel(tg.Bloom())
        (True, False)
    """
    if isinstance(module, nn.Sequential):
        return all(is_per_pixel(child) or getattr(child, "is_identity", False) for child in module)
    return getattr(module, "per_pixel", False)


def _per_pixel_from(stages: nn.ModuleList) -> int:
    """Index of the first of the stages that end the list and are all per pixel (``len(stages)`` where the last is not)."""
    index = len(stages)
    while index and is_per_pixel(stages[index - 1]):
        index -= 1
    return index


def _look_stages(module: nn.Module) -> tuple:
    """``(stateful first stage or None, [stage, ...])`` of any exportable module."""
    listed = getattr(module, "stages", None)
    stages = list(listed().values()) if callable(listed) else [module]
    stateful = stages.pop(0) if stages and frame_of(stages[0]) is not None else None
    return stateful, stages


def has_state(module: nn.Module) -> bool:
    """Whether ``module``'s graph carries state between frames (inputs ``adapted``, ``dt``; output ``adapted_out``).

    Examples:
        >>> import torchgrade as tg
        >>> has_state(tg.PostFX(exposure={}, tonemap="neutral")), has_state(tg.ToneMap())
        (True, False)
    """
    return _look_stages(module)[0] is not None


def _export_form(stage: nn.Module, options: dict) -> nn.Module:
    """``stage.export_form(...)`` with the options it takes by name; the stage itself without one."""
    form = getattr(stage, "export_form", None)
    if form is None:
        return stage
    accepted = inspect.signature(form).parameters
    return form(**{name: value for name, value in options.items() if name in accepted})


def export_graph(module: nn.Module, lut_backend: str = "slices", grade_inputs: bool = False,
                 frames: FrameFormat = FrameFormat(), strips: bool = True) -> ExportGraph:
    """The export-ready form of ``module`` (see the module docstring for how each stage is asked).

    Examples:
        >>> import torchgrade as tg
        >>> export_graph(tg.ColorGrade(contrast=10), grade_inputs=True).stages[0].aces
        False
    """
    exposure, named = _look_stages(module)
    options = {"backend": backend_named(lut_backend)}
    stages: list[nn.Module] = []
    for stage in named:
        if grade_inputs and isinstance(stage, ColorGrade):
            stages.append(GradeWithInputs(stage.aces, stage.curves(), stage.log_space))
        else:
            stages.append(_export_form(stage, options))
    if grade_inputs and not any(isinstance(s, GradeWithInputs) for s in stages):
        raise ValueError("grade_inputs=True needs a ColorGrade stage (a look's grade, or a ColorGrade)")
    return ExportGraph(stages, exposure, frames, strips).eval()


def grade_of(module: Optional[nn.Module]) -> Optional[ColorGrade]:
    """The grade whose controls feed a ``grade_inputs`` graph: a grade itself, or a look's ``grade``.

    Examples:
        >>> import torchgrade as tg
        >>> grade_of(tg.PostFX(grade={"contrast": 10})).contrast
        10
    """
    if isinstance(module, ColorGrade):
        return module
    return getattr(module, "grade", None)


def grade_feeds(grade: Optional[ColorGrade], batch: int) -> dict:
    """Per-sample control tensors of ``grade`` (identity controls for ``None``), for a ``grade_inputs`` model.

    Examples:
        >>> grade_feeds(None, 2)["channel_mixer"].shape
        torch.Size([2, 3, 3])
    """
    values = grade.params() if grade is not None else {}
    feeds = {}
    for name in GRADE_INPUTS:
        default = ColorGrade.controls[name].default
        shape = (batch,) + torch.as_tensor(default).shape
        value = torch.as_tensor(values.get(name, default), dtype=torch.float32).detach()
        feeds[name] = value if value.shape == shape else value.expand(shape).clone()
    return feeds


def input_names(graph: ExportGraph) -> list:
    """Graph input names, in the order :class:`ExportGraph` takes them.

    Examples:
        >>> import torchgrade as tg
        >>> input_names(export_graph(tg.AutoExposure()))
        ['image', 'adapted', 'dt']
    """
    names = ["image"] + (["adapted", "dt"] if graph.exposure is not None else [])
    if any(isinstance(s, GradeWithInputs) for s in graph.stages):
        names += list(GRADE_INPUTS)
    return names


def output_names(graph: ExportGraph) -> list:
    """Graph output names: ``output``, and ``adapted_out`` for a graph with exposure state.

    Examples:
        >>> import torchgrade as tg
        >>> output_names(export_graph(tg.AutoExposure()))
        ['output', 'adapted_out']
    """
    return ["output", "adapted_out"] if graph.exposure is not None else ["output"]


def example_inputs(graph: ExportGraph, module: nn.Module, image: torch.Tensor) -> tuple:
    """Inputs to trace ``graph`` with: the image (the look's float ``(batch, 3, height, width)``, as the graph takes
    it: :func:`~torchgrade.onnx.frames.trace_input`), the exposure state and the grading controls.

    Examples:
        >>> import torchgrade as tg
        >>> len(example_inputs(export_graph(tg.AutoExposure()), None, default_example(None)))
        3
    """
    batch = image.shape[0]
    inputs = [trace_input(image, graph.frames)]
    if graph.exposure is not None:
        inputs += [torch.full((batch,), 0.5), torch.tensor(1.0 / 30.0)]
    if any(isinstance(s, GradeWithInputs) for s in graph.stages):
        # Controls that require grad are never treated as identity, so every grading step is traced.
        inputs += [v.requires_grad_() for v in grade_feeds(grade_of(module), batch).values()]
    return tuple(inputs)


def default_example(graph: Optional[ExportGraph]) -> torch.Tensor:
    """A ``(2, 3, 64, 64)`` trace input: every size is taken from runtime shapes, so any size traces.

    Examples:
        >>> default_example(None).shape
        torch.Size([2, 3, 64, 64])
    """
    return torch.rand(2, 3, 64, 64, generator=torch.Generator().manual_seed(0)) * 4.0
