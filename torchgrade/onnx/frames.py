"""How frames enter and leave an exported graph: layout, dtype and encoding of the image input and the output.

Decoders and render targets hand over interleaved frames, ``(batch, height, width, 3)`` (``"NHWC"``), as
``uint8``, ``uint16``, ``float16`` or ``float32``; PyTorch's looks take ``(batch, 3, height, width)``
(``"NCHW"``) scene-linear float. :class:`FrameFormat` says which a file takes and gives, and the graph converts
at its two ends (a ``Transpose``, a ``Cast``, the transfer):

* **Float inputs** (``float32``, ``float16``) are scene-linear, as the look takes them (HDR, unbounded above).
* **Integer inputs** (``uint8``, ``uint16``) are **sRGB-encoded code values** (0-255, 0-65535), decoded in the
  graph to linear light with the sRGB EOTF (IEC 61966-2-1, :func:`~torchgrade.color.transfer.srgb_to_linear`),
  1.0 the top code. That is what PNG, JPEG and video decoders give, and every stage (metering, bloom's threshold,
  the grade's log encodings, the tone curve) is defined on linear light: codes read as linear would put mid grey
  (linear 0.18) at code 46 instead of 118, and 8 linear bits leave shadows in steps of 1/255 where sRGB codes
  step by 1/3295 near black. An integer input is a display-referred frame (nothing above 1.0).
* **Outputs**: the encodings of :data:`OUTPUTS`, float ones in ``float32`` or ``float16``, in either layout.

Examples:
    >>> fmt = frame_format(input_dtype=torch.uint8, layout="NHWC", output="srgb8")
    >>> frame = model_input(torch.full((1, 3, 2, 2), 0.18), fmt)
    >>> frame.shape, frame.dtype, int(frame[0, 0, 0, 0])
    (torch.Size([1, 2, 2, 3]), torch.uint8, 118)
    >>> round(float(decode_frame(to_nchw(frame, "NHWC"), torch.uint8)[0, 0, 0, 0]), 4)
    0.1812
"""

from __future__ import annotations

from typing import Mapping, NamedTuple, Optional

import numpy as np
import onnx as onnx_lib  # the onnx package (absolute import), not this package
import torch
from onnx import TensorProto, helper

from ..base.images import check_image
from ..color.transfer import linear_to_srgb, srgb_to_linear

__all__ = ["LAYOUTS", "INPUT_DTYPES", "FLOAT_DTYPES", "OUTPUTS", "CODE_MAX", "FrameFormat", "frame_format", "read_frame_format", "metadata_of",
           "to_nchw", "from_nchw", "decode_frame", "encode_frame", "check_batch", "model_input", "trace_input", "eight_bit_codes", "retype_uint16"]

LAYOUTS = ("NCHW", "NHWC")
"""Image layouts: ``(batch, 3, height, width)`` (PyTorch's) and ``(batch, height, width, 3)`` (decoders', interleaved)."""

FLOAT_DTYPES = (torch.float32, torch.float16)
"""Dtypes of float inputs and outputs (the graph computes in float32 either way)."""

INPUT_DTYPES = (torch.float32, torch.float16, torch.uint8, torch.uint16)
"""Dtypes of the image input: scene-linear floats, sRGB code values (see the module docstring)."""

CODE_MAX = {torch.uint8: 255, torch.uint16: 65535}
"""Top code of each integer dtype (sRGB 1.0)."""

OUTPUTS = {
    "linear": "display-linear float, Rec.709 primaries, clamped to [0, 1] by the look's tone mapper "
              "(scene-linear and not clamped for a look without a tone mapper)",
    "srgb": "sRGB-encoded float in [0, 1] (IEC 61966-2-1), Rec.709 primaries, clamped to [0, 1] before encoding",
    "srgb8": "8-bit sRGB code values (uint8, 0-255), Rec.709 primaries, clamped to [0, 1] before encoding and rounded",
    "srgb16": "16-bit sRGB code values (uint16, 0-65535), Rec.709 primaries, clamped to [0, 1] before encoding and rounded",
}
"""Output encodings of an exported graph, and what each holds (written into the file's output doc string)."""

_CODE_OUTPUTS = {"srgb8": torch.uint8, "srgb16": torch.uint16}


class FrameFormat(NamedTuple):
    """The image input's dtype and layout, and the output's encoding, float dtype and layout (:func:`frame_format`)."""

    input_dtype: torch.dtype = torch.float32
    layout: str = "NCHW"
    output: str = "linear"
    float_dtype: torch.dtype = torch.float32
    output_layout: str = "NCHW"

    @property
    def output_dtype(self) -> torch.dtype:
        """The output's dtype: the integer of a code encoding, else :attr:`float_dtype`."""
        return _CODE_OUTPUTS.get(self.output, self.float_dtype)


def _named(value, choices, what: str):
    if value not in choices:
        raise ValueError(f"{what} must be one of {tuple(choices)}, got {value!r}")
    return value


def frame_format(input_dtype: Optional[torch.dtype] = None, layout: str = "NCHW", output: str = "linear",
                 io_dtype: torch.dtype = torch.float32, output_layout: Optional[str] = None) -> FrameFormat:
    """A checked :class:`FrameFormat`: ``input_dtype`` defaults to ``io_dtype`` (the float input's and float
    output's dtype, :data:`FLOAT_DTYPES`), ``output_layout`` to ``layout``; layouts are upper or lower case.

    Examples:
        >>> frame_format(layout="nhwc").output_layout
        'NHWC'
        >>> frame_format(input_dtype=torch.int8)
        Traceback (most recent call last):
        ...
        ValueError: input_dtype must be one of (torch.float32, torch.float16, torch.uint8, torch.uint16), got torch.int8
    """
    _checked_dtype(io_dtype, "io_dtype")
    _checked_dtype(input_dtype, "input_dtype")
    _named(io_dtype, FLOAT_DTYPES, "io_dtype")
    input_dtype = _named(io_dtype if input_dtype is None else input_dtype, INPUT_DTYPES, "input_dtype")
    layouts = [_named(str(value).upper(), LAYOUTS, name) for name, value in (("layout", layout), ("output_layout", output_layout or layout))]
    return FrameFormat(input_dtype, layouts[0], _named(output, OUTPUTS, "output"), io_dtype, layouts[1])


_METADATA = ("torchgrade.input_dtype", "torchgrade.layout", "torchgrade.output", "torchgrade.io_dtype", "torchgrade.output_layout")


def read_frame_format(metadata: Mapping[str, str]) -> FrameFormat:
    """The :class:`FrameFormat` a file's metadata states (see :func:`metadata_of`); files written before a key
    existed take its default.

    Examples:
        >>> read_frame_format(metadata_of(frame_format(torch.uint8, "NHWC"))).input_dtype
        torch.uint8
    """
    values = [metadata.get(key) for key in _METADATA]
    io_dtype, input_dtype = (None if value is None else _checked_dtype(getattr(torch, value, value), name)
                             for name, value in (("io_dtype", values[3]), ("input_dtype", values[0])))
    return frame_format(input_dtype, values[1] or "NCHW", values[2] or "linear", io_dtype or torch.float32, values[4])


def _checked_dtype(value: object, name: str) -> Optional[torch.dtype]:
    """``value``, a ``torch.dtype`` or ``None``; ``TypeError`` naming ``name`` for anything else."""
    if value is not None and not isinstance(value, torch.dtype):
        raise TypeError(f"{name} must be a torch.dtype, got {value!r}")
    return value


def metadata_of(fmt: FrameFormat) -> dict:
    """``metadata_props`` entries that state ``fmt`` (what :func:`read_frame_format` reads).

    Examples:
        >>> metadata_of(frame_format(torch.uint8, "NHWC"))["torchgrade.input_dtype"]
        'uint8'
    """
    values = (fmt.input_dtype, fmt.layout, fmt.output, fmt.float_dtype, fmt.output_layout)
    return {key: str(value).replace("torch.", "") for key, value in zip(_METADATA, values)}


def to_nchw(image: torch.Tensor, layout: str) -> torch.Tensor:
    """``image`` in ``layout`` as ``(batch, 3, height, width)``.

    Examples:
        >>> to_nchw(torch.zeros(1, 4, 5, 3), "NHWC").shape
        torch.Size([1, 3, 4, 5])
    """
    return image.permute(0, 3, 1, 2) if layout == "NHWC" else image


def from_nchw(image: torch.Tensor, layout: str) -> torch.Tensor:
    """``(batch, 3, height, width)`` ``image`` in ``layout``.

    Examples:
        >>> from_nchw(torch.zeros(1, 3, 4, 5), "NHWC").shape
        torch.Size([1, 4, 5, 3])
    """
    return image.permute(0, 2, 3, 1) if layout == "NHWC" else image


def decode_frame(image: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """The float32 linear light of an input of ``dtype``: floats as they are, integer sRGB codes through the EOTF.

    Examples:
        >>> decode_frame(torch.tensor([0, 255], dtype=torch.uint8), torch.uint8).tolist()
        [0.0, 1.0]
    """
    if dtype not in CODE_MAX:
        return image.float()
    return srgb_to_linear(image.float() * (1.0 / CODE_MAX[dtype]))


def encode_frame(image: torch.Tensor, output: str = "linear", dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """A look's linear output in one of the :data:`OUTPUTS` encodings; a float encoding in ``dtype``.

    In an ONNX export ``srgb16`` gives float codes: the exporter's TorchScript tracer has no uint16, so
    :func:`retype_uint16` appends the ``Cast``.

    Examples:
        >>> encode_frame(torch.tensor([0.0, 0.18, 1.0, 4.0]), "srgb8").tolist()
        [0, 118, 255, 255]
    """
    encoded = image if _named(output, OUTPUTS, "output") == "linear" else linear_to_srgb(image.clamp(0.0, 1.0))
    if output in _CODE_OUTPUTS:
        codes = torch.round(encoded * float(CODE_MAX[_CODE_OUTPUTS[output]]))
        return codes if output == "srgb16" and torch.onnx.is_in_onnx_export() else codes.to(_CODE_OUTPUTS[output])
    return encoded if encoded.dtype == dtype else encoded.to(dtype)  # a Cast to its own type is a copy of the frame


def check_batch(image) -> torch.Tensor:
    """``image`` if it is a look's input, a float ``(batch, 3, height, width)`` tensor (:func:`~torchgrade.base.images.check_image`
    and a batch axis); otherwise the error that names what it is.

    Examples:
        >>> check_batch(torch.zeros(2, 9, 11, 3))
        Traceback (most recent call last):
        ...
        ValueError: image must have shape (..., 3, H, W) with 3 colour channels, got (2, 9, 11, 3)
    """
    check_image(image)
    if image.dim() != 4:
        raise ValueError(f"image must be a batch, (batch, 3, height, width), got {tuple(image.shape)}")
    return image


def model_input(image: torch.Tensor, fmt: FrameFormat) -> torch.Tensor:
    """The look's input ``image`` (float ``(batch, 3, height, width)``, scene-linear) as a file of ``fmt`` takes it:
    in its layout, in its dtype; for an integer input the sRGB codes of ``image`` clamped to [0, 1], rounded.

    Examples:
        >>> model_input(torch.tensor([0.0, 0.5, 2.0]).reshape(1, 3, 1, 1), frame_format(torch.uint16)).flatten().tolist()
        [0, 48192, 65535]
    """
    image = check_batch(image)
    if fmt.input_dtype in CODE_MAX:
        codes = torch.round(linear_to_srgb(image.float().clamp(0.0, 1.0)) * float(CODE_MAX[fmt.input_dtype]))
        image = codes.to(fmt.input_dtype)
    else:
        image = image.to(fmt.input_dtype)
    return from_nchw(image, fmt.layout).contiguous()


def trace_input(image: torch.Tensor, fmt: FrameFormat) -> torch.Tensor:
    """:func:`model_input` for the exporter's trace: uint16 codes as int32 (its tracer has no uint16; :func:`retype_uint16`
    names the input uint16 afterwards).

    Examples:
        >>> trace_input(torch.ones(1, 3, 2, 2), frame_format(torch.uint16)).dtype
        torch.int32
    """
    image = model_input(image, fmt)
    return image.to(torch.int32) if image.dtype == torch.uint16 else image


def eight_bit_codes(values: np.ndarray, output: str) -> np.ndarray:
    """An output of encoding ``output`` in 8-bit sRGB code units (float64), as a display shows it.

    Examples:
        >>> eight_bit_codes(np.array([0.18, 4.0]), "linear").round(2).tolist(), eight_bit_codes(np.array([257]), "srgb16").tolist()
        ([117.65, 255.0], [1.0])
    """
    values = np.asarray(values, dtype=np.float64)
    if output == "linear":
        return linear_to_srgb(torch.from_numpy(values).clamp(0.0, 1.0)).numpy() * 255.0
    return {"srgb": values * 255.0, "srgb8": values, "srgb16": values / 257.0}[_named(output, OUTPUTS, "output")]


def retype_uint16(model: onnx_lib.ModelProto, fmt: FrameFormat) -> onnx_lib.ModelProto:
    """Give a traced graph its uint16 ends: the int32 stand-in image input named uint16 (its first reader is a
    ``Cast`` to float, which reads either), and a ``Cast`` to uint16 after the float codes of an ``srgb16`` output.

    Examples:
        >>> graph = helper.make_graph([helper.make_node("Cast", ["image"], ["output"], to=TensorProto.FLOAT)], "g",
        ...     [helper.make_tensor_value_info("image", TensorProto.INT32, None)],
        ...     [helper.make_tensor_value_info("output", TensorProto.FLOAT, None)])
        >>> model = retype_uint16(helper.make_model(graph), frame_format(torch.uint16, output="srgb16"))
        >>> [node.op_type for node in model.graph.node], model.graph.input[0].type.tensor_type.elem_type == TensorProto.UINT16
        (['Cast', 'Cast'], True)
    """
    graph = model.graph
    if fmt.input_dtype == torch.uint16:
        graph.input[0].type.tensor_type.elem_type = TensorProto.UINT16
    if fmt.output == "srgb16":
        output = graph.output[0]
        for node in graph.node:
            node.output[:] = [f"{output.name}_codes" if name == output.name else name for name in node.output]
        graph.node.append(helper.make_node("Cast", [f"{output.name}_codes"], [output.name], to=TensorProto.UINT16))
        output.type.tensor_type.elem_type = TensorProto.UINT16
    return model
