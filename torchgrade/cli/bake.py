"""``torchgrade bake``: bake a look's grade and tone mapping into a ``.cube`` 3D LUT.

Examples:
    >>> import tempfile, pathlib
    >>> from torchgrade.cli import main
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     main(["bake", "-o", str(pathlib.Path(folder) / "look.cube"), "--size", "65", "--contrast", "20"])  # doctest: +ELLIPSIS
    bake: 65³ logc LUT of ColorGrade -> ToneMap, ... s -> ...look.cube
    error: p99.9 0.48, max 2.48 8-bit codes on 16384 realistic colours (tolerance 1 at p99.9); on colour charts: ...
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
from ..lut import ENTRY_CHOICES, LUTAccuracyWarning, srgb_code_error
from ..lut.bake import LOOK_SHAPER, bake_look, live_stages
from ..lut.shapers import DEFAULT_SIZES, SHAPERS, LogCExtendedShaper
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


def _cube_shaper(shaper: str) -> str:
    """``--shaper``: ``auto`` is ``logc``, the ``.cube`` form of the lattice a look is baked on
    (:data:`~torchgrade.lut.bake.LOOK_SHAPER`): its planes up to 58.86 are the ``"logc"`` lattice's at
    :attr:`~torchgrade.lut.shapers.LogCExtendedShaper.cube_size`, plane for plane, and a ``.cube`` 1D section stops
    there; the tail above it lives on in ``bake_lut``, ``to_lut`` and CLF files.

    Examples:
        >>> _cube_shaper("auto"), _cube_shaper("fitted")
        ('logc', 'fitted')
    """
    return "logc" if shaper == "auto" else shaper


def _cube_size(size, shaper: str):
    """``--size``, or when not given the default lattice's ``.cube`` form for ``logc`` and the shaper's default size for
    the others (:data:`~torchgrade.lut.shapers.DEFAULT_SIZES`).

    Examples:
        >>> _cube_size(None, "logc") == LogCExtendedShaper.cube_size, _cube_size(None, "linear"), _cube_size(17, "logc")
        (True, 33, 17)
    """
    if size is not None:
        return size
    return _look_cube_size() if shaper == "logc" else DEFAULT_SIZES[shaper]


def _look_cube_size() -> int:
    """The ``.cube`` size of the default lattice (:attr:`~torchgrade.lut.shapers.LogCExtendedShaper.cube_size`)."""
    shaper = SHAPERS[LOOK_SHAPER]
    assert isinstance(shaper, LogCExtendedShaper)
    return shaper.cube_size


def run_bake(args: argparse.Namespace) -> str:
    """Check the arguments, bake, write the ``.cube``; the line to print (with the error on ``--scene``). A LUT over
    ``--report-tolerance`` is not written without ``--accept-error``
    (:class:`~torchgrade.cli.common.LUTOverTolerance`)."""
    _check_bake_arguments(args)
    refuse_overwriting([args.output], [args.config, args.scene, *(args.frames or ())])
    look = look_from_args(args)
    transform = look.per_pixel_stages()
    scene = None if args.scene is None else read_rec709(args.scene).unsqueeze(0)
    frames = [read_rec709(path) for path in args.frames] if args.frames else None
    tolerance = 0.5 if args.tolerance is None else args.tolerance
    start = time.perf_counter()
    with warnings.catch_warnings():  # the report is printed below, with its cause and advice
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        shaper = _cube_shaper(args.shaper)
        lut = bake_look(look, size=_cube_size(args.size, shaper), shaper=shaper, scene=scene, tolerance=tolerance,
                        progress=True, report_tolerance=args.report_tolerance, entries=args.entries, frames=frames)
    elapsed = time.perf_counter() - start
    refuse_lut_over_tolerance(lut.error_report, args.accept_error, REMEDIES.format(size=lut.size))
    title = Path(args.output).stem.replace('"', "")
    write_cube(args.output, lut, title=title)
    line = f"bake: {lut.size}³ {lut.shaper} LUT of {stages_label(transform)}, {elapsed:.1f} s -> {args.output}"
    if scene is not None:
        with torch.no_grad():
            received = look.per_pixel_input(scene)
            error = srgb_code_error(transform(received.double()), lut(received))
        line += f"; on {Path(args.scene).name}: {error:.2f} 8-bit codes at p99.9"
    live = live_stages(look)
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
    bake.add_argument("--size", type=_lut_size, help=f"points per axis, 2..256, or auto (needs --scene); default "
                      f"{_look_cube_size()} for logc (the default lattice's planes to 58.86), "
                      f"{DEFAULT_SIZES['linear']} for the others")
    bake.add_argument("--shaper", choices=("auto", "linear", "logc", "fitted"), default="auto",
                      help="default auto: logc (LogC to 58.86, what a .cube 1D section holds of the default lattice); "
                      "fitted: per-channel shaper fitted to the look (and --scene)")
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
