"""``torchgrade demo``: render the built-in HDR scene with the default look to an sRGB PNG.

Examples:
    >>> import tempfile, pathlib
    >>> from torchgrade.cli import main
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     main(["demo", "-o", str(pathlib.Path(folder) / "demo.png"), "--width", "64", "--height", "36"])  # doctest: +ELLIPSIS
    demo: 64x36, AutoExposure -> Bloom -> ColorGrade -> ToneMap, ... ms -> ...demo.png
    0
"""

from __future__ import annotations

import argparse
import time

import torch

from ..io import write_exr
from ..look.postfx import PostFX
from ..scene import demo_scene
from .common import refuse_overwriting, stages_label, write_png

__all__ = ["DEFAULT_LOOK", "run_demo", "add_demo"]

DEFAULT_LOOK = {
    "exposure": {"metering": "histogram", "metering_mask": "center", "speed_to_light": 3.0, "speed_to_dark": 1.0,
                 "compensation_curve": [[-8, -4], [-2, 0]]},
    "bloom": {"mode": "scattering", "threshold": 1.0, "knee": 0.5, "intensity": 0.6, "scatter": 0.7, "clamp": 16.0},
    "grade": {
        "aces": True,
        "post_exposure": 0.3,
        "temperature": 8,
        "contrast": 15,
        "saturation": 10,
        "split_shadows": [0.45, 0.5, 0.56],
        "split_highlights": [0.56, 0.5, 0.45],
    },
    "tonemap": {"mode": "aces"},
}
"""The demo's look, ``export/looks/cinematic.json``: eye adaptation as the engines meter (the histogram's 40-90 %
band, centre-weighted, a compensation curve that keeps dark scenes dark: -4 stops at 8 stops under grey, none from 2
under), scattering bloom, a gentle warm and contrasty grade in ACES, ACES tone mapping."""


def run_demo(args: argparse.Namespace) -> str:
    """Render the scene, write the PNG (and the scene as EXR with ``--exr``); the line to print.

    Examples:
        >>> import tempfile, pathlib
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     args = argparse.Namespace(output=str(pathlib.Path(folder) / "demo.png"), exr=None, width=32, height=18)
        ...     run_demo(args)  # doctest: +ELLIPSIS
        'demo: 32x18, AutoExposure -> Bloom -> ColorGrade -> ToneMap, ... ms -> ...demo.png'
    """
    refuse_overwriting([args.output, args.exr], [])
    look = PostFX.from_config(DEFAULT_LOOK)
    start = time.perf_counter()
    scene = demo_scene(args.height, args.width)
    with torch.no_grad():
        graded = look(scene)[0]
    elapsed = time.perf_counter() - start
    write_png(args.output, graded)
    if args.exr:
        write_exr(args.exr, scene[0])
    return f"demo: {args.width}x{args.height}, {stages_label(look)}, {elapsed * 1000:.0f} ms -> {args.output}"


def add_demo(commands) -> None:
    """The ``demo`` subcommand and its flags.

    Examples:
        >>> parser = argparse.ArgumentParser()
        >>> add_demo(parser.add_subparsers())
        >>> args = parser.parse_args(["demo"])
        >>> args.output, args.width, args.height
        ('demo.png', 640, 360)
    """
    demo = commands.add_parser("demo", help="render the built-in HDR scene with the default look")
    demo.add_argument("--output", "-o", default="demo.png", help="sRGB PNG to write (default demo.png)")
    demo.add_argument("--exr", help="also write the scene-referred linear scene to this EXR")
    demo.add_argument("--width", type=int, default=640)
    demo.add_argument("--height", type=int, default=360)
    demo.set_defaults(run=run_demo)
