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
import struct
import time
import warnings
import zlib
from pathlib import Path

import numpy as np
import torch

from ..base.budget import check_pixels
from ..base.files import open_regular
from ..color import srgb_to_linear
from ..grading.layer import ColorGrade
from ..io import exr_info
from ..io.atomic import atomic_write
from ..lut import LUTAccuracyWarning
from ..match import GRADE_CONTROLS, LUT_FILES, match_look
from ..tonemap import TONEMAP_MODES
from .common import read_rec709, refuse_overwriting, report_line

__all__ = ["run_match", "add_match", "read_target", "png_size", "MAX_PNG_BYTES"]

MAX_PNG_BYTES = 1 << 30
"""Largest PNG file read as a target (its pixels pass the pixel budget, :data:`torchgrade.base.budget.MAX_PIXELS`)."""

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(header: bytes, path) -> tuple:
    """``(height, width)`` from a PNG's first 24 bytes: its signature, then the IHDR chunk's length (13), type and
    width and height (4-byte big-endian, 1 to 2³¹ - 1; PNG specification, 3rd edition, §5.2, §11.2.1).

    Examples:
        >>> png_size(PNG_SIGNATURE + struct.pack(">I4sII", 13, b"IHDR", 30000, 30000), "bomb.png")
        (30000, 30000)
        >>> png_size(b"GIF89a", "after.png")
        Traceback (most recent call last):
        ...
        ValueError: target after.png is not a PNG file: it does not start with a PNG signature and IHDR chunk
    """
    if len(header) < 24 or header[:8] != PNG_SIGNATURE or header[8:16] != struct.pack(">I4s", 13, b"IHDR"):
        raise ValueError(f"target {path} is not a PNG file: it does not start with a PNG signature and IHDR chunk")
    width, height = struct.unpack(">II", header[16:24])
    if not (0 < width < 2**31 and 0 < height < 2**31):
        raise ValueError(f"target {path}: its IHDR chunk declares {width}x{height} pixels (1 to 2^31 - 1 each)")
    return height, width


def read_target(path: Path, size: tuple | None = None) -> torch.Tensor:
    """The target picture as ``(3, H, W)`` linear: an 8-bit PNG decoded from sRGB, or an EXR in Rec.709.

    Its header is read first, a PNG's IHDR (:func:`png_size`) or an EXR's data windows
    (:func:`~torchgrade.io.exr_info`): a picture over the pixel budget, or of another ``size`` ``(height, width)``
    than the source's, is refused before a pixel is decoded. A PNG is decoded from the handle its header was read
    from, so no other file can take its place in between; an EXR is read within the source's pixel count.

    Examples:
        >>> import tempfile
        >>> from .common import write_png
        >>> after = Path(tempfile.mkdtemp()) / "after.png"
        >>> write_png(after, torch.full((3, 2, 2), 0.18))
        >>> round(read_target(after).mean().item(), 3)   # code 118, decoded
        0.181
        >>> read_target(after, (135, 240))  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: target .../after.png is 2x2 pixels and the source 240x135: a look is matched pixel for pixel, so both must be the same size
    """
    if path.suffix.lower() == ".exr":
        _check_size(path, {part.size() for part in exr_info(path)}, size)
        return read_rec709(path, **({} if size is None else {"max_pixels": size[0] * size[1]}))
    if path.suffix.lower() != ".png":
        raise ValueError(f"target must be an .exr or .png file, got {path}")
    with open_regular(path, MAX_PNG_BYTES, "target") as handle:
        height, width = png_size(handle.read(24), path)
        check_pixels(height, width, f"target {path}")
        _check_size(path, {(height, width)}, size)
        handle.seek(0)
        return _decoded_png(handle, path)


def _check_size(path: Path, sizes: set, size: tuple | None) -> None:
    """``ValueError`` unless the source's ``size`` (``None``: any) is one of the target's ``sizes``."""
    if size is not None and tuple(size) not in sizes:
        height, width = min(sizes)
        raise ValueError(f"target {path} is {width}x{height} pixels and the source {size[1]}x{size[0]}: a look is "
                         "matched pixel for pixel, so both must be the same size")


def _decoded_png(handle, path: Path) -> torch.Tensor:
    """The PNG's pixels from ``handle``, decoded from sRGB; a damaged file (a bad chunk, a truncated or garbled image
    stream) is a ``ValueError`` naming it, whatever PIL raised."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(handle, formats=["PNG"]) as image:
            codes = np.asarray(image.convert("RGB"), dtype=np.float32)
    except UnidentifiedImageError:  # its message names the file handle, not the file
        raise ValueError(f"target {path} is not a readable PNG file (a damaged chunk)") from None
    except (OSError, SyntaxError, EOFError, zlib.error, Image.DecompressionBombError) as error:
        raise ValueError(f"target {path} is not a readable PNG file ({error})") from None
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
    source = read_rec709(args.source)
    target = read_target(Path(args.target), tuple(source.shape[-2:]))
    stages = ("grade",) if args.scene_referred else ("grade", "tonemap")
    start = time.perf_counter()
    result = match_look(source, target, stages, controls=args.controls, tonemaps=args.tonemap, steps=args.steps,
                        residual=args.residual, max_pixels=args.max_pixels)
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
        >>> args.tonemap, args.steps, args.max_pixels, len(args.controls)
        (['agx'], 100, 16384, 12)
    """
    match = commands.add_parser("match", help="learn a look's controls (and a residual LUT) from a before/after pair")
    match.add_argument("source", help="scene-referred linear OpenEXR file (before)")
    match.add_argument("target", help="the same picture after the look: .png (sRGB) or .exr (display-referred linear)")
    match.add_argument("--output", "-o", required=True, help="look JSON to write (a PostFX config)")
    match.add_argument("--cube", help="also bake the fitted look (with its residual LUT) into this .cube (or .clf) file")
    match.add_argument("--cube-size", type=int, default=65, help="points per axis of the .cube (default 65)")
    match.add_argument("--tonemap", action="append", choices=TONEMAP_MODES,
                       help="tone mapper to fit (repeat to try several; default: every SDR mode)")
    match.add_argument("--controls", type=_controls, default=GRADE_CONTROLS,
                       help=f"comma-separated grading controls to fit (default {','.join(GRADE_CONTROLS)})")
    match.add_argument("--residual", action="store_true", help="fit a 17³ residual LUT on top of the controls")
    match.add_argument("--scene-referred", action="store_true", help="the target is a graded EXR without tone mapping")
    match.add_argument("--steps", type=int, default=100,
                       help="Levenberg-Marquardt trials of each phase of the full fit (default 100)")
    match.add_argument("--max-pixels", type=int, default=16384, help="pixels the controls are fitted on (default 16384)")
    match.set_defaults(run=run_match)
