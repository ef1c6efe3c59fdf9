"""``torchgrade bake``: bake a look's grade and tone mapping into a ``.cube`` 3D LUT.

Examples:
    >>> import tempfile, pathlib
    >>> from torchgrade.cli import main
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     main(["bake", "-o", str(pathlib.Path(folder) / "look.cube"), "--size", "65", "--contrast", "20"])  # doctest: +ELLIPSIS
    bake: 65³ logc LUT of ColorGrade -> ToneMap, ... s -> ...look.cube
    error: p99.9 0.48, max 2.48 8-bit codes on 16384 realistic colours (tolerance 1 at p99.9); worst case: ...
    0

At the default 39³ the same look misses realistic colours by p99.9 1.15 codes: the command writes nothing, prints the
report and what to do on stderr and returns :data:`~torchgrade.cli.common.OVER_TOLERANCE` (3), unless
``--accept-error`` is given.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import torch

from ..io import write_cube
from ..lut import ENTRY_CHOICES, LUTAccuracyWarning, bake_lut, srgb_code_error
from ..lut.bake import expects_hdr
from ..lut.shapers import DEFAULT_SIZES, LogCExtendedShaper
from .common import (add_grading_flags, look_from_args, read_rec709, refuse_lut_over_tolerance, refuse_overwriting,
                     report_line, stages_label)

__all__ = ["run_bake", "add_bake", "REMEDIES"]

REMEDIES = ("a larger lattice (--size above {size}; the report's advice names one that meets the tolerance, when one up to "
            "65³ does), a lattice and entries fitted to the shot (--scene SHOT.exr --shaper fitted --entries fitted), or the "
            "look applied directly (torchgrade grade)")
"""What a bake of ``size`` over its tolerance can do instead, as the refusal lists it (``str.format`` template)."""


def _lut_size(text: str):
    """``--size``: an integer, or ``auto`` (the smallest size within ``--tolerance`` on ``--scene``).

    Examples:
        >>> _lut_size("33"), _lut_size("auto")
        (33, 'auto')
    """
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer (points per axis) or auto, got {text!r}") from None


def _check_bake_arguments(args: argparse.Namespace) -> None:
    """Refuse, before any baking, what would fail or be ignored afterwards.

    Examples:
        >>> _check_bake_arguments(argparse.Namespace(output="look.cube", size="auto", scene=None, tolerance=None))
        Traceback (most recent call last):
        ...
        ValueError: --size auto needs --scene, the image to measure the error on
    """
    output = Path(args.output)
    if output.suffix.lower() != ".cube":
        raise ValueError(f"output must end in .cube, got {output}")
    if not output.parent.is_dir():
        raise ValueError(f"output folder {output.parent} does not exist")
    if output.is_dir():
        raise ValueError(f"output {output} is a folder")
    if args.size == "auto" and args.scene is None:
        raise ValueError("--size auto needs --scene, the image to measure the error on")
    if args.tolerance is not None and (args.size != "auto" or args.tolerance <= 0):
        raise ValueError(f"--tolerance goes with --size auto and must be above 0, got {args.tolerance}")


def _cube_shaper(shaper: str, transform) -> str:
    """``--shaper``: ``auto`` is ``logc`` for a look taking HDR input: the default lattice (``"logc_extended"``) as a
    ``.cube`` file can hold it. Its planes up to 58.86 are the ``"logc"`` lattice's at
    :attr:`~torchgrade.lut.shapers.LogCExtendedShaper.cube_size` (39³), plane for plane, and a ``.cube`` 1D section
    stops there; the tail above it lives on in ``bake_lut`` and CLF files.

    Examples:
        >>> from torchgrade import ToneMap
        >>> _cube_shaper("auto", ToneMap("aces")), _cube_shaper("auto", lambda image: image), _cube_shaper("fitted", None)
        ('logc', 'auto', 'fitted')
    """
    return "logc" if shaper == "auto" and expects_hdr(transform) else shaper


def _cube_size(size, shaper: str):
    """``--size``, or when not given the default lattice's ``.cube`` form for ``logc`` (39) and 33 for the others.

    Examples:
        >>> _cube_size(None, "logc"), _cube_size(None, "linear"), _cube_size(17, "logc")
        (39, 33, 17)
    """
    if size is not None:
        return size
    return LogCExtendedShaper.cube_size if shaper == "logc" else DEFAULT_SIZES["logc"]


def run_bake(args: argparse.Namespace) -> str:
    """Check the arguments, bake, write the ``.cube``; the line to print (with the error on ``--scene``). A LUT over
    ``--report-tolerance`` is not written without ``--accept-error``
    (:class:`~torchgrade.cli.common.LUTOverTolerance`)."""
    _check_bake_arguments(args)
    refuse_overwriting([args.output], [args.config, args.scene, *(args.frames or ())])
    look = look_from_args(args)
    transform = look.per_pixel_stages()
    live = [name for name in look.stages() if name not in ("grade", "primary", "tonemap")]
    scene = None
    if args.scene is not None:
        with torch.no_grad():
            scene = look.per_pixel_input(read_rec709(args.scene).unsqueeze(0))
    frames = None
    if args.frames:
        with torch.no_grad():
            frames = torch.cat([look.per_pixel_input(read_rec709(path).unsqueeze(0)).reshape(3, 1, -1) for path in args.frames], dim=-1)
    tolerance = 0.5 if args.tolerance is None else args.tolerance
    start = time.perf_counter()
    with warnings.catch_warnings():  # the report is printed below, with its cause and advice
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        shaper = _cube_shaper(args.shaper, transform)
        lut = bake_lut(transform, size=_cube_size(args.size, shaper), shaper=shaper, scene=scene, tolerance=tolerance, progress=True,
                       report_tolerance=args.report_tolerance, entries=args.entries, frames=frames)
    elapsed = time.perf_counter() - start
    refuse_lut_over_tolerance(lut.error_report, args.accept_error, REMEDIES.format(size=lut.size))
    title = Path(args.output).stem.replace('"', "")
    write_cube(args.output, lut, title=title)
    line = f"bake: {lut.size}³ {lut.shaper} LUT of {stages_label(transform)}, {elapsed:.1f} s -> {args.output}"
    if scene is not None:
        with torch.no_grad():
            error = srgb_code_error(transform(scene.double()), lut(scene))
        line += f"; on {Path(args.scene).name}: {error:.2f} 8-bit codes at p99.9"
    if live:
        line += f"; left live, not in the LUT: {', '.join(live)}"
    return f"{line}\n{report_line(lut.error_report)}"


def add_bake(commands) -> None:
    """The ``bake`` subcommand and its flags.

    Examples:
        >>> parser = argparse.ArgumentParser()
        >>> add_bake(parser.add_subparsers())
        >>> args = parser.parse_args(["bake", "-o", "look.cube", "--size", "auto", "--contrast", "20"])
        >>> args.size, args.contrast, args.shaper
        ('auto', 20.0, 'auto')
    """
    bake = commands.add_parser("bake", help="bake grade and tone mapping into a .cube 3D LUT")
    bake.add_argument("--output", "-o", required=True, help=".cube file to write")
    bake.add_argument("--config", help="look JSON (PostFX config); without it, the grading flags below")
    bake.add_argument("--size", type=_lut_size, help="points per axis, 2..256, or auto (needs --scene); default 39 for logc "
                      "(the default lattice's planes to 58.86), 33 for the others")
    bake.add_argument("--shaper", choices=("auto", "linear", "logc", "fitted"), default="auto",
                      help="default auto: logc (LogC to 58.86, what a .cube 1D section holds) when the look tone maps; fitted: per-channel shaper fitted to the look (and --scene)")
    bake.add_argument("--scene", help="EXR the look will grade: the lattice covers its range after the look's exposure and bloom, "
                      "and the error is reported on it")
    bake.add_argument("--frames", action="append", metavar="EXR",
                      help="an EXR of the footage the LUT is for (repeat for several): the report is measured on its pixels "
                      "instead of the realistic colours")
    bake.add_argument("--tolerance", type=float, help="with --size auto: 8-bit sRGB codes at p99.9 (default 0.5)")
    bake.add_argument("--report-tolerance", type=float, default=1.0,
                      help="8-bit sRGB codes at p99.9 on realistic colours (and --scene) above which the report names a cause "
                      "and a fix and the LUT is not written (default 1)")
    bake.add_argument("--accept-error", action="store_true",
                      help="write a LUT over --report-tolerance anyway (else exit status 3 and nothing written)")
    bake.add_argument("--entries", choices=ENTRY_CHOICES, default="sampled",
                      help="fitted: refine the table for the smallest largest error on validation colours and --scene (seconds)")
    add_grading_flags(bake)
    bake.set_defaults(run=run_bake)
