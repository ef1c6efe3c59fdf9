"""The ``torchgrade`` command: ``demo`` renders the built-in scene, ``grade`` grades an EXR file."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from . import TONEMAP_MODES, ColorGrade, PostFX, ToneMap
from .color import linear_to_srgb
from .io import read_exr, write_exr
from .io.atomic import atomic_write
from .scene import demo_scene


DEFAULT_LOOK = {
    "bloom": {"mode": "scattering", "threshold": 1.0, "knee": 0.5, "intensity": 0.6, "scatter": 0.7},
    "grade": {
        "aces": True,
        "post_exposure": 0.5,
        "temperature": 8.0,
        "contrast": 15.0,
        "saturation": 10.0,
        "split_shadows": (0.45, 0.5, 0.56),
        "split_highlights": (0.56, 0.5, 0.45),
    },
    "tonemap": "aces",
}
"""The demo's look: scattering bloom, a gentle warm and contrasty grade in ACES, ACES tone mapping."""


def write_png(path, display_linear: torch.Tensor) -> None:
    """Write a display-referred linear ``(3, H, W)`` image as an 8-bit sRGB PNG (atomically)."""
    from PIL import Image

    codes = (linear_to_srgb(display_linear.clamp(0.0, 1.0)) * 255.0).round().to(torch.uint8)
    pixels = np.ascontiguousarray(codes.permute(1, 2, 0).cpu().numpy())
    atomic_write(path, lambda temporary: Image.fromarray(pixels, "RGB").save(temporary, format="PNG"))


def _stages(look: nn.Module) -> str:
    return " -> ".join(type(stage).__name__ for stage in look.children())


def _write_output(path: Path, image: torch.Tensor) -> None:
    if path.suffix.lower() == ".exr":
        write_exr(path, image)
    elif path.suffix.lower() == ".png":
        write_png(path, image)
    else:
        raise ValueError(f"output must end in .png or .exr, got {path}")


def run_demo(args: argparse.Namespace) -> str:
    look = PostFX.from_config(DEFAULT_LOOK)
    start = time.perf_counter()
    scene = demo_scene(args.height, args.width)
    with torch.no_grad():
        graded = look(scene)[0]
    elapsed = time.perf_counter() - start
    write_png(args.output, graded)
    if args.exr:
        write_exr(args.exr, scene[0])
    return f"demo: {args.width}x{args.height}, {_stages(look)}, {elapsed * 1000:.0f} ms -> {args.output}"


def _grade_from_args(args: argparse.Namespace) -> nn.Sequential:
    controls = {
        name: getattr(args, name)
        for name in ("post_exposure", "temperature", "tint", "contrast", "hue_shift", "saturation")
        if getattr(args, name) is not None
    }
    return nn.Sequential(ColorGrade(aces=args.tonemap == "aces", **controls), ToneMap(args.tonemap))


def run_grade(args: argparse.Namespace) -> str:
    image = read_exr(args.input)[:3]
    look = _grade_from_args(args)
    start = time.perf_counter()
    with torch.no_grad():
        graded = look(image.unsqueeze(0))[0]
    elapsed = time.perf_counter() - start
    _write_output(Path(args.output), graded)
    height, width = image.shape[1:]
    return f"grade: {width}x{height}, {_stages(look)}, {elapsed * 1000:.0f} ms -> {args.output}"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="torchgrade", description="Differentiable HDR post-processing.")
    commands = parser.add_subparsers(dest="command", required=True)

    demo = commands.add_parser("demo", help="render the built-in HDR scene with the default look")
    demo.add_argument("--output", "-o", default="demo.png", help="sRGB PNG to write (default demo.png)")
    demo.add_argument("--exr", help="also write the scene-referred linear scene to this EXR")
    demo.add_argument("--width", type=int, default=640)
    demo.add_argument("--height", type=int, default=360)
    demo.set_defaults(run=run_demo)

    grade = commands.add_parser("grade", help="grade and tone map an OpenEXR image")
    grade.add_argument("input", help="scene-referred linear OpenEXR file")
    grade.add_argument("--output", "-o", required=True, help=".png (sRGB, 8-bit) or .exr (display linear)")
    grade.add_argument("--tonemap", choices=TONEMAP_MODES, default="aces")
    for flag, unit in (
        ("--post-exposure", "stops"),
        ("--temperature", "-100..100"),
        ("--tint", "-100..100"),
        ("--contrast", "-100..100"),
        ("--hue-shift", "degrees, -180..180"),
        ("--saturation", "-100..100"),
    ):
        grade.add_argument(flag, type=float, help=unit)
    grade.set_defaults(run=run_grade)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        print(args.run(args))
    except (ValueError, TypeError, FileNotFoundError) as error:
        print(f"torchgrade {args.command}: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
