"""Export a look to ONNX, verify it with onnxruntime on real EXRs, and report error, size and speed.

    python export/export_onnx.py --config export/looks/cinematic.json --out look.onnx
    python -m export --config export/looks/cinematic.json --out look.onnx --lut 33

Prints, for the exported file: the max abs error against PyTorch on each EXR (display-referred,
outputs in [0, 1] for a tone-mapped look), the node count and the median onnxruntime latency.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

import torchgrade as tg

DEFAULT_EXR_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "exr"
DEFAULT_IMAGES = ("Desk.exr", "Carrots.exr", "GoldenGate.exr")


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True, type=Path, help="look config (JSON, see torchgrade.pipeline)")
    parser.add_argument("--out", required=True, type=Path, help="ONNX file to write")
    parser.add_argument("--lut", type=int, metavar="SIZE", help="bake grade + tone mapping into a SIZE³ LUT first")
    parser.add_argument("--interpolation", choices=tg.lut.INTERPOLATIONS, default="tetrahedral")
    parser.add_argument("--lut-backend", choices=tg.onnx.LUT_BACKENDS, default="strip")
    parser.add_argument("--grade-inputs", action="store_true", help="grading controls as graph inputs")
    parser.add_argument("--exr-dir", type=Path, default=DEFAULT_EXR_DIR)
    parser.add_argument("--images", nargs="+", default=DEFAULT_IMAGES, help="EXR files (in --exr-dir) to verify on")
    return parser.parse_args(argv)


def graph_inputs(look: tg.PostFX, image: torch.Tensor):
    """The image, plus a starting adaptation state and dt = 0 when the look has exposure."""
    if look.exposure is None:
        return image
    return image, torch.zeros(image.shape[0]), torch.tensor(0.0)


def main(argv=None) -> int:
    args = parse_args(argv)
    look = tg.PostFX.from_config(args.config).eval()
    if args.lut:
        look = look.to_lut(args.lut, args.interpolation)
    tg.onnx.export(look, args.out, lut_backend=args.lut_backend, grade_inputs=args.grade_inputs)
    print(f"{args.out}: stages {' -> '.join(look.stages())}, {tg.onnx.node_count(args.out)} nodes")
    images = [tg.io.read_exr(args.exr_dir / name)[:3].unsqueeze(0) for name in args.images]
    for name, image in zip(args.images, images):
        error = tg.onnx.verify(look, args.out, graph_inputs(look, image))
        print(f"  {name} {tuple(image.shape[-2:])}: max abs error vs PyTorch {error:.2e}")
    latency = tg.onnx.latency_ms(args.out, graph_inputs(look, images[0]), look)
    print(f"  onnxruntime latency on {args.images[0]}: {latency:.1f} ms (median of 5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
