"""Export a look to ONNX, verify it with onnxruntime on real EXRs, and report error, size and speed.

    python export/export_onnx.py --config export/looks/cinematic.json --out look.onnx
    python -m export --config export/looks/cinematic.json --out look.onnx --lut 65 --output srgb8

Prints, for the exported file: the node count, the max abs error against PyTorch on each EXR on
onnxruntime and OpenVINO (float32 and its default precision; display-referred, outputs in [0, 1] for a
tone-mapped look, 8-bit codes with ``--output srgb8``) and the median latency on each.
The work is :func:`torchgrade.onnx.export_look`, which ``torchgrade export`` runs too. As there, a ``--lut``
bake over its tolerance is refused with its report and what to do, exit status 3, unless ``--accept-error``.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import torchgrade as tg
from torchgrade.cli.common import OVER_TOLERANCE, LUTOverTolerance, refuse_lut_over_tolerance
from torchgrade.cli.export import REMEDIES

DEFAULT_EXR_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "exr"
DEFAULT_IMAGES = ("Desk.exr", "Carrots.exr", "GoldenGate.exr")


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True, type=Path, help="look config (JSON, see torchgrade.look.postfx)")
    parser.add_argument("--out", required=True, type=Path, help="ONNX file to write")
    parser.add_argument("--lut", type=int, metavar="SIZE", help="bake grade + tone mapping into a SIZE³ LUT first")
    parser.add_argument("--accept-error", action="store_true", help="export a LUT over its tolerance anyway")
    parser.add_argument("--interpolation", choices=tg.lut.INTERPOLATIONS, default="tetrahedral")
    parser.add_argument("--lut-backend", choices=tg.onnx.LUT_BACKENDS, default="strip")
    parser.add_argument("--grade-inputs", action="store_true", help="grading controls as optional graph inputs")
    parser.add_argument("--output", choices=tg.onnx.OUTPUTS, default="linear", help="output encoding")
    parser.add_argument("--whole-frame", action="store_true", help="per-pixel stages on the whole frame, not in strips")
    parser.add_argument("--exr-dir", type=Path, default=DEFAULT_EXR_DIR)
    parser.add_argument("--images", nargs="+", default=DEFAULT_IMAGES, help="EXR files (in --exr-dir) to verify on")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    look = tg.PostFX.from_config(args.config).eval()
    if args.lut:
        with warnings.catch_warnings():  # the report is printed with the export, or refused with what to do
            warnings.simplefilter("ignore", tg.lut.LUTAccuracyWarning)
            look = look.to_lut(args.lut, args.interpolation)
        try:
            refuse_lut_over_tolerance(look.lut.error_report, args.accept_error, REMEDIES.format(size=args.lut))
        except LUTOverTolerance as error:
            print(f"export: error: {error}", file=sys.stderr)
            return OVER_TOLERANCE
    images = {name: tg.io.read_exr(args.exr_dir / name)[:3].unsqueeze(0) for name in args.images}
    print("\n".join(tg.onnx.export_look(look, args.out, images, args.lut_backend, args.grade_inputs, args.output, not args.whole_frame)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
