"""``torchgrade grade``: grade and tone map an OpenEXR image to PNG or EXR.

Examples:
    >>> import tempfile, pathlib, torch
    >>> from torchgrade.cli import main
    >>> from torchgrade.io import write_exr
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     source = pathlib.Path(folder) / "in.exr"
    ...     write_exr(source, torch.rand(3, 8, 8) * 4)
    ...     main(["grade", str(source), "-o", str(pathlib.Path(folder) / "out.png"), "--contrast", "20"])  # doctest: +ELLIPSIS
    grade: 8x8, ColorGrade -> ToneMap, ... ms -> ...out.png
    0
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from ..display import DISPLAY_PRESETS, Display, display_settings, write_png16
from ..io import read_exr
from .common import add_grading_flags, grade_from_args, stages_label, write_image

__all__ = ["run_grade", "add_grade"]


def run_grade(args: argparse.Namespace) -> str:
    """Grade ``args.input`` with the grading flags and write ``args.output``; the line to print."""
    image = read_exr(args.input)[:3]
    look = grade_from_args(args)
    if args.display:
        look.append(Display(**display_settings(args.display, look[-1])))
    start = time.perf_counter()
    with torch.no_grad():
        graded = look(image.unsqueeze(0))[0]
    elapsed = time.perf_counter() - start
    if args.display and Path(args.output).suffix.lower() == ".png":
        write_png16(args.output, graded)
    else:  # with --display, an .exr holds the display's signal (half floats: within half a 10-bit code)
        write_image(Path(args.output), graded)
    height, width = image.shape[1:]
    return f"grade: {width}x{height}, {stages_label(look)}, {elapsed * 1000:.0f} ms -> {args.output}"


def add_grade(commands) -> None:
    """The ``grade`` subcommand and its flags."""
    grade = commands.add_parser("grade", help="grade and tone map an OpenEXR image")
    grade.add_argument("input", help="scene-referred linear OpenEXR file")
    grade.add_argument("--output", "-o", required=True, help=".png (sRGB, 8-bit) or .exr (display linear)")
    grade.add_argument("--display", choices=tuple(DISPLAY_PRESETS),
                       help="encode for this display (hdr_pq: Rec.2100 PQ at an HDR --tonemap's peak) and write its signal: 16-bit .png or .exr")
    add_grading_flags(grade)
    grade.set_defaults(run=run_grade)
