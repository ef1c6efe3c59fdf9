"""``torchgrade match``: learn a look from a before/after pair and write it as a look JSON (and a ``.cube``).

Examples:
    >>> import tempfile, pathlib, torch
    >>> import torchgrade as tg
    >>> from torchgrade.cli import main
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     before, after = pathlib.Path(folder) / "before.exr", pathlib.Path(folder) / "after.exr"
    ...     scene = tg.scene.demo_scene(12, 16)[0]
    ...     tg.io.write_exr(before, scene, half=False)
    ...     tg.io.write_exr(after, tg.PostFX(grade={"contrast": 20}, tonemap="neutral")(scene[None])[0], half=False)
    ...     main(["match", str(before), str(after), "-o", str(pathlib.Path(folder) / "look.json"),
    ...           "--tonemap", "neutral", "--controls", "contrast", "--steps", "20"])  # doctest: +ELLIPSIS
    match: neutral, 1 controls, ... s; held-out error ... codes p99.9 ... -> ...look.json
    0
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from ..base.budget import check_pixels
from ..base.files import open_regular
from ..color import srgb_to_linear
from ..grading.layer import ColorGrade
from ..io.atomic import atomic_write
from ..lut import LUTAccuracyWarning
from ..match import GRADE_CONTROLS, LUT_FILES, match_look
from ..tonemap import TONEMAP_MODES
from .common import read_rec709, refuse_overwriting, report_line

__all__ = ["run_match", "add_match", "read_target", "MAX_PNG_BYTES"]

MAX_PNG_BYTES = 1 << 30
"""Largest PNG file read as a target (its pixels pass the pixel budget, :data:`torchgrade.base.budget.MAX_PIXELS`)."""


def read_target(path: Path) -> torch.Tensor:
    """The target picture as ``(3, H, W)`` linear: an 8-bit PNG decoded from sRGB, or an EXR in Rec.709.

    Examples:
        >>> import tempfile
        >>> from .common import write_png
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     write_png(Path(folder) / "after.png", torch.full((3, 2, 2), 0.18))
        ...     round(read_target(Path(folder) / "after.png").mean().item(), 3)   # code 118, decoded
        0.181
    """
    if path.suffix.lower() == ".exr":
        return read_rec709(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"target must be an .exr or .png file, got {path}")
    from PIL import Image

    with open_regular(path, MAX_PNG_BYTES, "target") as handle, Image.open(handle) as image:
        check_pixels(image.height, image.width, f"target {path}")  # from its header: nothing decoded yet
        codes = np.asarray(image.convert("RGB"), dtype=np.float32)
    return srgb_to_linear(torch.from_numpy(codes / 255.0).permute(2, 0, 1).contiguous()).double()


def _controls(text: str) -> tuple:
    """``--controls``: comma-separated names of :class:`~torchgrade.ColorGrade` controls.

    Examples:
        >>> _controls("contrast, saturation")
        ('contrast', 'saturation')
    """
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in ColorGrade.controls]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown grading control(s) {unknown}; known: {', '.join(ColorGrade.controls)}")
    return names


def _check_outputs(args: argparse.Namespace) -> None:
    for path, suffixes in ((Path(args.output), (".json",)), (None if args.cube is None else Path(args.cube), LUT_FILES)):
        if path is None:
            continue
        if path.suffix.lower() not in suffixes:
            raise ValueError(f"{path} must end in {' or '.join(suffixes)}")
        if not path.parent.is_dir():
            raise ValueError(f"output folder {path.parent} does not exist")
    if args.scene_referred and (args.residual or args.cube):
        raise ValueError("--residual and --cube need a display-referred target (leave out --scene-referred)")


def _errors(errors: dict) -> str:
    return f"{errors['p99.9']:.2f} codes p99.9 (max {errors['max']:.1f}), mean ΔE2000 {errors['delta_e_2000']:.3f}"


def run_match(args: argparse.Namespace) -> str:
    """Fit the look, write the JSON (and the ``.cube`` or ``.clf``); the line to print (the module shows a run)."""
    _check_outputs(args)
    refuse_overwriting([args.output, args.cube], [args.source, args.target])
    source, target = read_rec709(args.source), read_target(Path(args.target))
    stages = ("grade",) if args.scene_referred else ("grade", "tonemap")
    start = time.perf_counter()
    result = match_look(source, target, stages, controls=args.controls, tonemaps=args.tonemap, steps=args.steps,
                        lm_steps=args.lm_steps, residual=args.residual, max_pixels=args.max_pixels)
    elapsed = time.perf_counter() - start
    config = result.look.to_config()
    text = json.dumps(config, indent=2) + "\n"
    atomic_write(args.output, lambda temporary: Path(temporary).write_text(text))
    mode = config.get("tonemap", {}).get("mode", "scene-referred")
    line = f"match: {mode}, {len(args.controls)} controls, {elapsed:.1f} s; held-out error {_errors(result.errors['controls'])}"
    if "residual" in result.errors:
        line += f"; with the residual LUT {_errors(result.errors['residual'])}"
    line += f" -> {args.output}"
    if args.cube:
        with warnings.catch_warnings():  # the report is printed below, with its cause and advice
            warnings.simplefilter("ignore", LUTAccuracyWarning)
            baked = result.write_lut(args.cube, size=args.cube_size)
        line += f", {args.cube} ({baked['size']}³: {_errors(baked)})\n{report_line(baked['report'])}"
    return line


def add_match(commands) -> None:
    """The ``match`` subcommand and its flags.

    Examples:
        >>> parser = argparse.ArgumentParser()
        >>> add_match(parser.add_subparsers())
        >>> args = parser.parse_args(["match", "before.exr", "after.png", "-o", "look.json", "--tonemap", "agx"])
        >>> args.tonemap, args.steps, args.lm_steps, len(args.controls)
        (['agx'], 200, 100, 12)
    """
    match = commands.add_parser("match", help="learn a look's controls (and a residual LUT) from a before/after pair")
    match.add_argument("source", help="scene-referred linear OpenEXR file (before)")
    match.add_argument("target", help="the same picture after the look: .png (sRGB) or .exr (display-referred linear)")
    match.add_argument("--output", "-o", required=True, help="look JSON to write (a PostFX config)")
    match.add_argument("--cube", help="also bake the fitted look (with its residual LUT) into this .cube (or .clf) file")
    match.add_argument("--cube-size", type=int, default=65, help="points per axis of the .cube (default 65)")
    match.add_argument("--tonemap", action="append", choices=TONEMAP_MODES,
                       help="tone mapper to fit (repeat to try several; default: the usual SDR modes)")
    match.add_argument("--controls", type=_controls, default=GRADE_CONTROLS,
                       help=f"comma-separated grading controls to fit (default {','.join(GRADE_CONTROLS)})")
    match.add_argument("--residual", action="store_true", help="fit a 17³ residual LUT on top of the controls")
    match.add_argument("--scene-referred", action="store_true", help="the target is a graded EXR without tone mapping")
    match.add_argument("--steps", type=int, default=200, help="Adam steps (default 200)")
    match.add_argument("--lm-steps", type=int, default=100, help="Levenberg-Marquardt trials after Adam (default 100)")
    match.add_argument("--max-pixels", type=int, default=8192, help="pixels the controls are fitted on (default 8192)")
    match.set_defaults(run=run_match)
