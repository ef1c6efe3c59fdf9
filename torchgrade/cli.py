"""The ``torchgrade`` command: ``demo`` renders the built-in scene, ``grade`` grades an EXR file,
``bake`` writes a look's grade and tone mapping as a ``.cube`` 3D LUT, ``export`` writes a look as ONNX and
verifies it on onnxruntime."""

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
from .io import read_exr, write_cube, write_exr
from .io.atomic import atomic_write
from .lut import INTERPOLATIONS, LUT_BACKENDS, bake_lut, srgb_code_error
from .onnx import export_look
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


GRADING_FLAGS = {
    "post_exposure": "stops",
    "temperature": "-100..100",
    "tint": "-100..100",
    "contrast": "-100..100",
    "hue_shift": "degrees, -180..180",
    "saturation": "-100..100",
}
"""The grading controls ``grade`` and ``bake`` take as flags (``--post-exposure`` ...), with their units."""


def _grade_from_args(args: argparse.Namespace) -> nn.Sequential:
    controls = {name: getattr(args, name) for name in GRADING_FLAGS if getattr(args, name) is not None}
    tonemap = args.tonemap or "aces"
    return nn.Sequential(ColorGrade(aces=tonemap == "aces", **controls), ToneMap(tonemap))


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


def _lut_size(text: str):
    """``--size``: an integer, or ``auto`` (the smallest size within ``--tolerance`` on ``--scene``)."""
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer (points per axis) or auto, got {text!r}") from None


def _look_to_bake(args: argparse.Namespace) -> PostFX:
    """The look to bake: from ``--config``, or from the grading flags."""
    if args.config is None:
        grade, tonemap = _grade_from_args(args)
        return PostFX(grade=grade, tonemap=tonemap)
    given = [name for name in (*GRADING_FLAGS, "tonemap") if getattr(args, name) is not None]
    if given:
        raise ValueError(f"give --config or grading flags, not both (got --config and {', '.join('--' + n.replace('_', '-') for n in given)})")
    return PostFX.from_config(args.config)


def _check_bake_arguments(args: argparse.Namespace) -> None:
    """Refuse, before any baking, what would fail or be ignored afterwards."""
    output = Path(args.output)
    if output.suffix.lower() != ".cube":
        raise ValueError(f"output must end in .cube, got {output}")
    if not output.parent.is_dir():
        raise ValueError(f"output folder {output.parent} does not exist")
    if args.size == "auto" and args.scene is None:
        raise ValueError("--size auto needs --scene, the image to measure the error on")
    if args.tolerance is not None and (args.size != "auto" or args.tolerance <= 0):
        raise ValueError(f"--tolerance goes with --size auto and must be above 0, got {args.tolerance}")


def run_bake(args: argparse.Namespace) -> str:
    _check_bake_arguments(args)
    look = _look_to_bake(args)
    transform = look.per_pixel_stages()
    live = [name for name in look.stages() if name not in ("grade", "primary", "tonemap")]
    scene = None
    if args.scene is not None:
        with torch.no_grad():
            scene = look.per_pixel_input(read_exr(args.scene)[:3].unsqueeze(0))
    tolerance = 0.5 if args.tolerance is None else args.tolerance
    start = time.perf_counter()
    lut = bake_lut(transform, size=args.size, shaper=args.shaper, scene=scene, tolerance=tolerance, progress=True)
    elapsed = time.perf_counter() - start
    title = Path(args.output).stem.replace('"', "")
    write_cube(args.output, lut, title=title)
    line = f"bake: {lut.size}³ {lut.shaper} LUT of {_stages(transform)}, {elapsed:.1f} s -> {args.output}"
    if scene is not None:
        with torch.no_grad():
            error = srgb_code_error(transform(scene.double()), lut(scene))
        line += f"; on {Path(args.scene).name}: {error:.2f} 8-bit codes at p99.9"
    if live:
        line += f"; left live, not in the LUT: {', '.join(live)}"
    return line


def run_export(args: argparse.Namespace) -> str:
    output = Path(args.out)
    if output.suffix.lower() != ".onnx" or not output.parent.is_dir():
        raise ValueError(f"output must be a .onnx file in an existing folder, got {output}")
    look = PostFX.from_config(args.config).eval()
    if args.lut is not None:
        look = look.to_lut(args.lut, args.interpolation)
    if args.scene:
        images = {Path(path).name: read_exr(path)[:3].unsqueeze(0) for path in args.scene}
    else:
        images = {"demo scene": demo_scene(args.height, args.width)}
    return "\n".join(export_look(look, output, images, args.lut_backend, args.grade_inputs))


def _add_grading_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tonemap", choices=TONEMAP_MODES, help="default aces")
    for name, unit in GRADING_FLAGS.items():
        parser.add_argument("--" + name.replace("_", "-"), type=float, help=unit)


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
    _add_grading_flags(grade)
    grade.set_defaults(run=run_grade)

    bake = commands.add_parser("bake", help="bake grade and tone mapping into a .cube 3D LUT")
    bake.add_argument("--output", "-o", required=True, help=".cube file to write")
    bake.add_argument("--config", help="look JSON (PostFX config); without it, the grading flags below")
    bake.add_argument("--size", type=_lut_size, default=33, help="points per axis, 2..256, or auto (needs --scene; default 33)")
    bake.add_argument("--shaper", choices=("auto", "linear", "logc"), default="auto", help="default auto: logc when the look tone maps")
    bake.add_argument("--scene", help="EXR the look will grade: the lattice covers its range after the look's exposure and bloom, "
                      "and the error is reported on it")
    bake.add_argument("--tolerance", type=float, help="with --size auto: 8-bit sRGB codes at p99.9 (default 0.5)")
    _add_grading_flags(bake)
    bake.set_defaults(run=run_bake)

    export = commands.add_parser("export", help="export a look to ONNX; print node count, error vs PyTorch and latency")
    export.add_argument("--config", required=True, help="look JSON (PostFX config)")
    export.add_argument("--out", "-o", required=True, help=".onnx file to write")
    export.add_argument("--lut", type=int, metavar="SIZE", help="bake grade and tone mapping into a SIZE³ LUT first")
    export.add_argument("--interpolation", choices=INTERPOLATIONS, default="tetrahedral", help="the LUT's (with --lut)")
    export.add_argument("--lut-backend", choices=LUT_BACKENDS, default="strip", help="the LUT's graph form (default strip, opset 17)")
    export.add_argument("--grade-inputs", action="store_true", help="grading controls as graph inputs")
    export.add_argument("--scene", nargs="+", help="EXR files to verify on (default: the built-in scene)")
    export.add_argument("--width", type=int, default=320, help="built-in scene width")
    export.add_argument("--height", type=int, default=180, help="built-in scene height")
    export.set_defaults(run=run_export)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        print(args.run(args))
    except (ValueError, TypeError, OSError) as error:
        print(f"torchgrade {args.command}: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
