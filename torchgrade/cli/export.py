"""``torchgrade export``: write a look as ONNX; print its node count, its error against PyTorch and its latency
on onnxruntime and on OpenVINO (float32 and its default precision).

Examples:
    >>> import json, tempfile, pathlib
    >>> from torchgrade.cli import main
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     config = pathlib.Path(folder) / "look.json"
    ...     _ = config.write_text(json.dumps({"tonemap": "aces"}))
    ...     code = main(["export", "--config", str(config), "-o", str(pathlib.Path(folder) / "look.onnx"),
    ...                  "--width", "32", "--height", "18"])  # doctest: +ELLIPSIS
    /.../look.onnx: stages tonemap, input float32 NCHW, output linear NCHW, ... nodes
      demo scene (18, 32): max abs error vs PyTorch: openvino default ..., openvino f32 ..., onnxruntime ...
      latency on demo scene: openvino default ... ms, openvino f32 ... ms, onnxruntime ... ms (median of 5)
    >>> code
    0
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import torch

from ..look.postfx import PostFX
from ..lut import INTERPOLATIONS, LUT_BACKENDS, LUTAccuracyWarning
from ..onnx import INPUT_DTYPES, IO_DTYPES, LAYOUTS, OUTPUTS, export_look
from ..scene import demo_scene
from .common import read_rec709, refuse_lut_over_tolerance, refuse_overwriting

__all__ = ["run_export", "add_export", "REMEDIES"]

REMEDIES = ("a larger lattice (--lut above {size}; the report's advice names one that meets the tolerance, when one up to 65³ "
            "does), or the look exported as it is (no --lut)")
"""What an ``export --lut`` of ``size`` over its tolerance can do instead, as the refusal lists it (``str.format`` template)."""


def run_export(args: argparse.Namespace) -> str:
    """Export ``--config`` (baked to a LUT with ``--lut``), verify on the scenes; the lines to print. A LUT over its
    tolerance is not exported without ``--accept-error`` (:class:`~torchgrade.cli.common.LUTOverTolerance`)."""
    output = Path(args.out)
    if output.suffix.lower() != ".onnx" or not output.parent.is_dir():
        raise ValueError(f"output must be a .onnx file in an existing folder, got {output}")
    refuse_overwriting([output], [args.config, *(args.scene or ())])
    look = PostFX.from_config(args.config).eval()
    if args.lut is not None:
        with warnings.catch_warnings():  # the report is printed with the export, or refused with what to do
            warnings.simplefilter("ignore", LUTAccuracyWarning)
            look = look.to_lut(args.lut, args.interpolation)
        assert look.lut is not None  # to_lut's look holds the baked LUT
        refuse_lut_over_tolerance(look.lut.error_report, args.accept_error, REMEDIES.format(size=args.lut))
    if args.scene:
        images = {Path(path).name: read_rec709(path).unsqueeze(0) for path in args.scene}
    else:
        images = {"demo scene": demo_scene(args.height, args.width)}
    frames = {"io_dtype": getattr(torch, args.io_dtype), "input_dtype": args.input_dtype and getattr(torch, args.input_dtype),
              "layout": args.layout, "output_layout": args.output_layout, "optional_inputs": not args.required_inputs}
    return "\n".join(export_look(look, output, images, args.lut_backend, args.grade_inputs, args.output, not args.whole_frame, **frames))


def add_export(commands) -> None:
    """The ``export`` subcommand and its flags."""
    export = commands.add_parser("export", help="export a look to ONNX; print node count, error vs PyTorch and latency")
    export.add_argument("--config", required=True, help="look JSON (PostFX config)")
    export.add_argument("--out", "-o", required=True, help=".onnx file to write")
    export.add_argument("--lut", type=int, metavar="SIZE", help="bake grade and tone mapping into a SIZE³ LUT first")
    export.add_argument("--accept-error", action="store_true", help="export a LUT over its tolerance (p99.9 1 code on "
                        "realistic colours) anyway (else exit status 3 and nothing written)")
    export.add_argument("--interpolation", choices=INTERPOLATIONS, default="tetrahedral", help="the LUT's (with --lut)")
    export.add_argument("--lut-backend", choices=LUT_BACKENDS, default="slices", help="the LUT's graph form (default slices, opset 17)")
    export.add_argument("--grade-inputs", action="store_true", help="grading controls as optional graph inputs")
    export.add_argument("--output", choices=OUTPUTS, default="linear", help="output encoding (default display-linear float)")
    names = [str(dtype).replace("torch.", "") for dtype in INPUT_DTYPES]
    export.add_argument("--input-dtype", choices=names, help="image input dtype: float scene-linear, or uint8/uint16 sRGB codes "
                        "decoded to linear in the graph (default: --io-dtype)")
    export.add_argument("--io-dtype", choices=[str(dtype).replace("torch.", "") for dtype in IO_DTYPES], default="float32", help="dtype of a float input and a float output")
    export.add_argument("--layout", type=str.upper, choices=LAYOUTS, default="NCHW", help="image input layout (NHWC: interleaved frames)")
    export.add_argument("--output-layout", type=str.upper, choices=LAYOUTS, help="output layout (default: --layout)")
    export.add_argument("--required-inputs", action="store_true",
                        help="adapted, dt and grading controls as plain inputs fed every call (OpenVINO, TensorRT), not optional ones")
    export.add_argument("--whole-frame", action="store_true",
                        help="per-pixel stages on the whole frame: a graph without a Scan over strips of rows")
    export.add_argument("--scene", nargs="+", help="EXR files to verify on (default: the built-in scene)")
    export.add_argument("--width", type=int, default=320, help="built-in scene width")
    export.add_argument("--height", type=int, default=180, help="built-in scene height")
    export.set_defaults(run=run_export)
