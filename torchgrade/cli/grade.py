"""``torchgrade grade``: grade and tone map an OpenEXR image, or a shot of them, to PNG, TIFF or EXR.

A shot is several inputs, a folder, a glob or a ``name.%04d.exr`` pattern, graded in frame order with
the look's eye adaptation carried from frame to frame; ``-o`` then names the frames with a pattern
(``out.%04d.png``).

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
from functools import partial

from ..io import read_cube
from ..io.atomic import remove_interrupted
from ..io.exr import ADAPTATIONS, exr_info
from ..look.postfx import PostFX
from ..output.display import DISPLAY_PRESETS, display_settings
from ..output.layer import Display
from .common import (
    add_exposure_flags,
    add_grading_flags,
    exposure_from_args,
    given_exposure_flags,
    given_grading_flags,
    look_from_args,
    read_rec709,
    refuse_overwriting,
    stages_label,
)
from ..shots.frames import grade_shot, output_paths, shot_frames
from ..shots.outputs import BIT_DEPTHS, check_output, write_frame

__all__ = ["run_grade", "add_grade", "look_to_grade", "check_grading_memory", "GRADING_COPIES", "MAX_GRADING_BYTES"]


def look_to_grade(args: argparse.Namespace) -> PostFX:
    """The look ``grade`` applies: ``--config`` or the grading flags, with ``--lut`` in place of grade and tone mapping,
    and ``--look-lut`` after them."""
    look = _base_look(args)
    if args.look_lut is None:
        if args.look_lut_contribution is not None:
            raise ValueError("--look-lut-contribution needs --look-lut")
        return look
    if look.look_lut is not None:
        raise ValueError("the --config look has a look_lut already: give --look-lut without it, or edit the config")
    contribution = 1.0 if args.look_lut_contribution is None else args.look_lut_contribution
    slots = {name: stage for name, stage in look.stages().items()}
    return PostFX(**slots, look_lut={"lut": args.look_lut, "contribution": contribution})


def _base_look(args: argparse.Namespace) -> PostFX:
    """The look before ``--look-lut``: ``--config`` or the grading flags, or ``--lut`` in place of grade and tone mapping."""
    if args.lut is None:
        return look_from_args(args)
    if given_grading_flags(args):
        raise ValueError(f"--lut replaces grade and tone mapping: give it without {', '.join(given_grading_flags(args))}")
    config = {} if args.config is None else PostFX.from_config(args.config).to_config()
    if {"grade", "primary", "tonemap"} & set(config):
        raise ValueError("--lut replaces grade and tone mapping: the --config look may keep only exposure, bloom and dither")
    if given_exposure_flags(args):
        if args.config is not None:
            raise ValueError(f"give --config or {', '.join(given_exposure_flags(args))}, not both")
        config["exposure"] = exposure_from_args(args)
    return PostFX(**config, lut=read_cube(args.lut))


def _reader(args: argparse.Namespace):
    """Read a frame's RGB as asked, in Rec.709 unless told not to, over its display window so every frame of a
    shot keeps its frame."""
    return partial(read_rec709, to_rec709=args.to_rec709, adaptation=args.adaptation, layer=args.layer, view=args.view,
                   part=args.part, window="display")


GRADING_COPIES = 7
"""Frame-sized float32 RGB buffers grading one frame holds at its peak: the cinematic look to PNG took 6.4 times the
frame (1.24 GB above the process for a 4000x4000 frame, 310 MB for 2000x2000; the exposure, bloom's pyramid, the
strips' output, the encoding)."""

MAX_GRADING_BYTES = 8 << 30
"""Default of ``--max-bytes``: a 12000x12000 display window from a 364-byte file then stops before any work, where
it ran the machine out of memory (7.1 GB); an 8K frame (7680x4320) needs 2.8 GB."""


def check_grading_memory(frames: list, part, jobs: int, max_bytes: int) -> None:
    """Raise ``ValueError`` naming the frame and its display window when grading it (``jobs`` frames at once, at most
    as many as there are frames) would need more than ``max_bytes``, from the headers alone: a file's few bytes can
    ask for any canvas.

    Examples:
        >>> import tempfile, pathlib, torch
        >>> from torchgrade.io import write_exr
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     frame = pathlib.Path(folder) / "plate.exr"
        ...     write_exr(frame, torch.zeros(3, 100, 100))
        ...     check_grading_memory([frame], None, jobs=1, max_bytes=1 << 19)
        Traceback (most recent call last):
        ...
        ValueError: ...plate.exr: displayWindow 100x100 needs about 840000 bytes to grade (7 frames of 120000 bytes), above --max-bytes 524288
    """
    at_once = min(jobs, len(frames))
    for frame in frames:
        parts = exr_info(frame)
        chosen = [parts[part]] if isinstance(part, int) and 0 <= part < len(parts) else parts
        height, width = max((p.size("display") for p in chosen), key=lambda size: size[0] * size[1])
        frame_bytes = 4 * 3 * height * width
        need = frame_bytes * GRADING_COPIES * at_once
        if need > max_bytes:
            together = f", {at_once} at once" if at_once > 1 else ""
            raise ValueError(f"{frame}: displayWindow {width}x{height} needs about {need} bytes to grade ({GRADING_COPIES} "
                             f"frames of {frame_bytes} bytes{together}), above --max-bytes {max_bytes}")


def run_grade(args: argparse.Namespace) -> str:
    """Grade the frames ``args.inputs`` names and write them to ``args.output``; the line to print."""
    depth = check_output(args.output, args.bit_depth, args.scene_referred)
    frames = shot_frames(args.inputs)
    outputs = output_paths(args.output, frames)
    refuse_overwriting(outputs, [*frames, args.config, args.lut, args.look_lut], allowed=args.overwrite_input)
    remove_interrupted(outputs)  # what a run of these frames killed mid-write (SIGKILL) left beside them
    check_grading_memory(frames, args.part, args.jobs, args.max_bytes)
    look = look_to_grade(args)
    if args.display:
        look.display = Display(**display_settings(args.display, look.tonemap))
    if args.scene_referred and look.lut is not None:
        raise ValueError("--scene-referred stops before tone mapping, which --lut holds")
    if args.jobs < 1 or args.fps <= 0:
        raise ValueError(f"--jobs must be 1 or more and --fps above 0, got {args.jobs} and {args.fps}")
    sizes = {}

    def write(index, image):
        sizes[index] = tuple(image.shape[1:])
        write_frame(outputs[index], image, depth, encoded=look.display is not None)

    start = time.perf_counter()
    grade_shot(look, frames, _reader(args), write, 1.0 / args.fps, args.scene_referred, args.jobs, len(frames) > 1 and not args.quiet)
    elapsed = time.perf_counter() - start
    height, width = sizes[0]
    if len(frames) == 1:
        return f"grade: {width}x{height}, {stages_label(look)}, {elapsed * 1000:.0f} ms -> {args.output}"
    return f"grade: {len(frames)} frames, {width}x{height}, {stages_label(look)}, {len(frames) / elapsed:.1f} fps -> {args.output}"


def _add_shot_flags(grade: argparse.ArgumentParser) -> None:
    grade.add_argument("--config", help="look JSON (PostFX config); without it, the grading flags below")
    grade.add_argument("--lut", help=".cube 3D LUT applied in place of grade and tone mapping")
    grade.add_argument("--fps", type=float, default=24.0, help="frame rate of the shot, for eye adaptation (default 24)")
    grade.add_argument("--jobs", "-j", type=int, default=1, help="frames graded at once (looks without eye adaptation)")
    grade.add_argument("--bit-depth", choices=sorted({d for depths in BIT_DEPTHS.values() for d in depths}),
                       help="png: 8 (default) or 16; tif: 16 (default) or float; exr: half (default) or float")
    grade.add_argument("--scene-referred", action="store_true",
                       help="write the frame before tone mapping (after exposure, bloom and grade): .exr or float .tif")
    grade.add_argument("--layer", help="EXR layer to read (default the RGB(A) layer)")
    grade.add_argument("--view", help="view of a multi-view EXR")
    grade.add_argument("--part", type=lambda text: int(text) if text.isdigit() else text,
                       help="part of a multi-part EXR, by index or name")
    grade.add_argument("--to-rec709", action=argparse.BooleanOptionalAction, default=True,
                       help="convert each frame from the primaries its chromaticities attribute names (ACES AP0, XYZ...) to "
                       "linear Rec.709, the primaries the look works in (default); --no-to-rec709 grades the stored RGB as it is")
    grade.add_argument("--adaptation", choices=ADAPTATIONS, default="auto",
                       help="how --to-rec709 takes the file's white to D65: bradford (the ACES convention), none, or auto "
                       "(default: none for XYZ primaries, whose white is only X = Y = Z; bradford for RGB spaces)")
    grade.add_argument("--display", choices=tuple(DISPLAY_PRESETS),
                       help="encode for this display (hdr_pq: Rec.2100 PQ at an HDR --tonemap's peak) and write its signal: "
                       "16-bit .png or .tif, or .exr")
    grade.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    grade.add_argument("--max-bytes", type=int, default=MAX_GRADING_BYTES,
                       help=f"memory grading may take, judged from each frame's header before reading it (default {MAX_GRADING_BYTES})")
    grade.add_argument("--overwrite-input", action="store_true",
                       help="let graded frames replace the input frames they come from (refused otherwise)")


def add_grade(commands) -> None:
    """The ``grade`` subcommand and its flags."""
    grade = commands.add_parser("grade", help="grade and tone map an OpenEXR image or a shot of them")
    grade.add_argument("inputs", nargs="+", metavar="input",
                       help="scene-referred linear OpenEXR: files, folders, globs or name.%%04d.exr patterns")
    grade.add_argument("--output", "-o", required=True,
                       help=".png (sRGB), .tif (sRGB or float linear) or .exr (linear); out.%%04d.png for a shot")
    _add_shot_flags(grade)
    add_grading_flags(grade)
    add_exposure_flags(grade)
    looks = grade.add_argument_group("creative LUT (after tone mapping, as Unity URP's Color Lookup)")
    looks.add_argument("--look-lut", metavar="FILE", help="a .cube or CLF file applied to the tone-mapped image in sRGB codes")
    looks.add_argument("--look-lut-contribution", type=float, metavar="C", help="its blend in [0, 1] (default 1)")
    grade.set_defaults(run=run_grade)
