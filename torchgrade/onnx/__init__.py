"""ONNX export of torchgrade modules and looks, and verification with onnxruntime.

``export(module, path)`` writes one ONNX file that serves every batch size and resolution: the
image input ``"image"`` ``(batch, 3, height, width)`` and the output ``"output"`` have dynamic axes.

**Frames in and out** (:mod:`~torchgrade.onnx.frames`). ``layout="NHWC"`` takes ``(batch, height, width, 3)``
(interleaved, as decoders and render targets give frames; ``output_layout`` the output's), ``input_dtype`` takes
``float32``/``float16`` scene-linear or ``uint8``/``uint16`` sRGB code values, decoded to linear light in the
graph (the sRGB EOTF), and ``output="srgb8"``/``"srgb16"`` gives 8/16-bit sRGB codes.

**Exporter and opset.** torchgrade uses PyTorch's TorchScript-based exporter
(``torch.onnx.export(..., dynamo=False)``) at **opset 17** by default. Opset 17 keeps every model
within the operators that OpenVINO and TensorRT accept (the "Deployment portability" rule of the
design), and the exporter turns a look into a graph in about a second, where the dynamo exporter
takes minutes for the bloom pyramid's symbolic shapes and cannot lower to opset 17 (its
down-conversion writes opset-18 ``Split`` attributes into opset-17 files). Where PyTorch's
symbolic functions are missing or wrong for an op torchgrade uses, :mod:`~torchgrade.onnx.symbolics`
supplies them for the duration of the export.

**Stages.** The exporter asks each stage for its :meth:`~torchgrade.base.stage.Stage.export_form`
(:mod:`~torchgrade.onnx.graph`); a look lists its stages.

**LUTs.** ``lut_backend`` picks how a :class:`~torchgrade.lut.LUT3D` is looked up in the graph
(the LUT's ``export_form(interpolation, backend)``, from the kernel registry :data:`torchgrade.lut.KERNELS`):

* ``"slices"`` (default, opset 17): trilinear lookups use the ``(S, S, S)`` volume laid out as its
  blue slices side by side, an ``S x S²`` image sampled by two 4-D ``GridSample`` nodes and a lerp;
  tetrahedral lookups use gathers (no GridSample form exists for them);
* ``"gather"`` (opset 17): both interpolations as ``Gather`` nodes, exactly PyTorch's kernels;
* ``"volume"`` (opset 20): trilinear with one 5-D ``GridSample`` (mode ``"linear"``), which
  onnxruntime runs from 1.17 but OpenVINO rejects and TensorRT has mis-mapped; tetrahedral stays
  on gathers.

**Bloom.** In PyTorch the pyramid depth of :class:`~torchgrade.Bloom` follows the frame size
through Python integers, which tracing would freeze. The graph instead holds every level a frame
of up to :data:`~torchgrade.bloom.MAX_FRAME_SIDE` pixels a side can have and masks out, from the runtime shape, the
levels the frame at hand does not have (``bloom(..., fixed_depth=...)``), so one graph matches
PyTorch at every resolution up to that size.

**Strips.** The stages that end a look and are per pixel (grade, primary grade, tone mapping, a LUT, and the
output encoding) run in a ``Scan`` over strips of rows of about :data:`~torchgrade.onnx.strips.SCAN_STRIP_PIXELS` pixels, as
eager PyTorch runs them (:mod:`~torchgrade.onnx.strips`): each node's strip stays in cache instead of a pass over
the frame in memory. ``export(..., strips=False)`` keeps them on the whole frame.

**Exposure.** A model with an :class:`~torchgrade.AutoExposure` stage is stateless: it takes
``"image"``, ``"adapted"`` ``(batch,)`` (the previous frame's adapted luminance; ``<= 0`` starts
a sequence) and ``"dt"`` (seconds, a scalar), and returns ``"output"`` and ``"adapted"``
(named ``"adapted_out"``) for the next frame. ``adapted`` and ``dt`` are optional inputs
(:mod:`~torchgrade.onnx.defaults`) whose defaults adapt instantly: a still, or a shot's first frame, is the image
alone; video feeds both.

**Outputs and metadata.** ``output`` picks display-linear float, sRGB-encoded float or 8/16-bit sRGB
(:data:`OUTPUTS`); ``io_dtype=torch.float16`` takes and returns float16. Constants are folded at
export (:func:`fold_constants`), only the opset domains the nodes use are declared (:func:`used_opsets`), and
every file describes itself (:mod:`~torchgrade.onnx.describe`).

**Verification.** :func:`verify` runs a file on onnxruntime or OpenVINO (:data:`RUNTIMES`) and
returns the max abs difference from PyTorch; :func:`latency_ms` times it (:mod:`~torchgrade.onnx.verify`).

**Grading controls as inputs.** With ``grade_inputs=True`` every :class:`~torchgrade.ColorGrade`
control becomes a graph input named as the control, per sample: scalars ``(batch,)``
(``post_exposure``, ``temperature``, ``tint``, ``contrast``, ``split_balance``,
``shadows_start``, ``shadows_end``, ``highlights_start``, ``highlights_end``, ``hue_shift``,
``saturation``), colours ``(batch, 3)`` (``color_filter``, ``split_shadows``,
``split_highlights``, ``shadows``, ``midtones``, ``highlights``), trackballs ``(batch, 4)``
(``lift``, ``gamma``, ``gain``) and ``channel_mixer`` ``(batch, 3, 3)``, in Unity's units. Every
grading step is then in the graph, so one model serves any look (and a different look per
sample); :func:`grade_feeds` gives a grade's values. Each input is optional (listed by onnxruntime's
``get_inputs()``; the look's value is its default, :mod:`~torchgrade.onnx.defaults`) and clamped in the graph to its range.
Only the ``aces`` switch and the curves (a variable number of control points) stay baked.

Examples:
    >>> import tempfile, torch, torchgrade as tg
    >>> lut = tg.bake_lut(tg.ColorGrade(contrast=20), size=9)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = export(tg.PostFX(lut=lut, interpolation="trilinear"), folder + "/lut.onnx")
    ...     verify(lut.export_form("trilinear"), path, torch.rand(1, 3, 8, 8)) < 1e-5
    True
"""

from .describe import describe
from .exporter import DEFAULT_OPSET, IO_DTYPES, export
from .frames import (
    INPUT_DTYPES,
    LAYOUTS,
    OUTPUTS,
    FrameFormat,
    decode_frame,
    encode_frame,
    frame_format,
    model_input,
    read_frame_format,
)
from .graph import GRADE_INPUTS, grade_feeds
from .look import export_look, graph_inputs
from .verify import (
    RUNTIMES,
    OpenVINOSession,
    feeds,
    latency_ms,
    metadata,
    node_count,
    reference,
    session,
    verify,
)

__all__ = [
    "export", "verify", "session", "reference", "feeds", "graph_inputs", "metadata", "describe", "node_count",
    "latency_ms", "export_look", "grade_feeds", "FrameFormat", "frame_format", "read_frame_format", "model_input",
    "decode_frame", "encode_frame", "GRADE_INPUTS", "INPUT_DTYPES", "IO_DTYPES", "LAYOUTS", "OUTPUTS", "RUNTIMES",
    "DEFAULT_OPSET", "OpenVINOSession",
]
"""The names a user calls. The package also imports the export's building blocks (the graph forms, symbolics, strip
forms, graph inspection helpers) for its modules and the tests; they are not part of the API contract: import them
from their modules."""
