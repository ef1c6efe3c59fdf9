"""What the subcommands share: writing images, the grading flags and the look they build.

Examples:
    >>> import argparse
    >>> args = argparse.Namespace(tonemap=None, post_exposure=None, temperature=None, tint=None,
    ...                           contrast=20.0, hue_shift=None, saturation=None)
    >>> stages_label(grade_from_args(args))
    'ColorGrade -> ToneMap'
"""

from __future__ import annotations

import argparse
import os

import torch
from torch import nn

from .. import TONEMAP_MODES, ColorGrade, ToneMap
from ..io import read_exr
from ..look.postfx import PostFX
from ..shots.outputs import display_codes, write_png

__all__ = ["GRADING_FLAGS", "EXPOSURE_FLAGS", "refuse_overwriting", "read_rec709", "display_codes", "write_png", "report_line", "LUTOverTolerance", "OVER_TOLERANCE", "refuse_lut_over_tolerance", "stages_label", "grade_from_args", "given_grading_flags", "look_from_args",
           "add_grading_flags", "add_exposure_flags", "exposure_from_args", "given_exposure_flags"]

GRADING_FLAGS = {
    "post_exposure": "stops",
    "temperature": "-100..100",
    "tint": "-100..100",
    "contrast": "-100..100",
    "hue_shift": "degrees, -180..180",
    "saturation": "-100..100",
}
"""The grading controls ``grade`` and ``bake`` take as flags (``--post-exposure`` ...), with their units."""

EXPOSURE_FLAGS = {
    "metering": "mean, log or histogram (HDRP's Automatic Histogram, 40-90 %%)",
    "metering_mask": "average, center or spot",
    "histogram_percent": "LOW HIGH: the band of the histogram metering averages (default 40 90)",
    "compensation": "stops added to the metered exposure",
    "ev_limits": "MIN MAX: the metered exposure's limits, stops around middle grey",
    "fixed_exposure": "stops: expose by 2^STOPS, metering nothing",
}
"""The eye-adaptation flags of ``grade`` (``--metering`` ...): any of them puts an ``AutoExposure`` stage first."""


def refuse_overwriting(outputs, inputs, allowed: bool = False) -> None:
    """Raise ``ValueError`` when a file a command would write is one it reads, or two outputs are one file: the same
    path, or the same file through a symbolic or hard link (same device and inode). ``allowed`` lets output ``k``
    replace input ``k`` (``grade --overwrite-input``: a frame graded in place), never another input, which another
    frame may not have read yet, and never another output.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     plate = Path(folder) / "plate.exr"
        ...     _ = plate.write_bytes(b"")
        ...     refuse_overwriting([Path(folder) / "." / "plate.exr"], [plate])
        Traceback (most recent call last):
        ...
        ValueError: ... would replace the input ...plate.exr: pass --overwrite-input to grade in place
    """
    def identity(path):
        try:
            status = os.stat(path)
        except (FileNotFoundError, NotADirectoryError):
            return None
        return status.st_dev, status.st_ino

    inputs = list(inputs)
    read = {identity(path): path for path in inputs if path is not None}
    read.pop(None, None)
    written: dict = {}
    for index, path in enumerate(outputs):
        if path is None:
            continue
        key = identity(path)
        if key is None:
            key = os.path.realpath(path)  # not there yet: two outputs can still name it twice
        if key in written:
            raise ValueError(f"{written[key]} and {path} are the same file: each output needs a file of its own")
        written[key] = path
        if key in read and not allowed:
            raise ValueError(f"{path} would replace the input {read[key]}: pass --overwrite-input to grade in place")
        own = inputs[index] if index < len(inputs) and inputs[index] is not None else None
        if key in read and allowed and (own is None or identity(own) != key):
            raise ValueError(f"{path} would replace the input {read[key]}, which is not its own frame's: "
                             "--overwrite-input grades each frame in place only")


def read_rec709(path, to_rec709: bool = True, adaptation: str = "auto", **options) -> torch.Tensor:
    """The ``(3, H, W)`` RGB of an EXR in linear Rec.709, the primaries every look works in.

    A file whose ``chromaticities`` name other primaries (ACES AP0, XYZ) is converted, as
    :func:`torchgrade.io.read_exr` does with ``to_rec709=True`` (``adaptation="auto"``: Bradford for RGB
    spaces, none for XYZ); ``to_rec709=False`` keeps the file's RGB as it is. ``options`` go to ``read_exr``.
    """
    return read_exr(path, to_rec709=to_rec709, adaptation=adaptation, **options)[:3]


def report_line(report) -> str:
    """A baked LUT's :class:`~torchgrade.lut.ErrorReport` as the CLI prints it, flagged when over its tolerance.

    Examples:
        >>> from torchgrade.lut import ErrorReport
        >>> report_line(ErrorReport(1.5, 4.0, 100, 1.0))
        'error: OVER TOLERANCE: p99.9 1.50, max 4.00 8-bit codes on 100 validation colours (tolerance 1 at p99.9)'
    """
    verdict = "" if report.within else "OVER TOLERANCE: "
    return f"error: {verdict}{report}"


OVER_TOLERANCE = 3
"""Exit status of ``bake`` and ``export --lut`` when the baked LUT misses the look by more than its tolerance."""


class LUTOverTolerance(Exception):
    """A baked LUT over its tolerance, not accepted: the command exits with :data:`OVER_TOLERANCE`."""


def refuse_lut_over_tolerance(report, accepted: bool, remedies: str) -> None:
    """Raise :class:`LUTOverTolerance` with ``report`` and ``remedies`` (what to do, in flags) when ``report`` is over
    its tolerance and ``accepted`` (``--accept-error``) is false.

    Examples:
        >>> from torchgrade.lut import ErrorReport
        >>> refuse_lut_over_tolerance(ErrorReport(0.5, 4.0, 100, 1.0), False, "--size 65")  # within: nothing
        >>> refuse_lut_over_tolerance(ErrorReport(1.5, 4.0, 100, 1.0), False, "--size 65")
        Traceback (most recent call last):
        ...
        torchgrade.cli.common.LUTOverTolerance: the baked LUT misses the look by more than its tolerance, so nothing was written
          report: p99.9 1.50, max 4.00 8-bit codes on 100 validation colours (tolerance 1 at p99.9)
          do one of: --size 65; or --accept-error to write it as it is
    """
    if report.within or accepted:
        return
    raise LUTOverTolerance(f"the baked LUT misses the look by more than its tolerance, so nothing was written\n"
                           f"  report: {report}\n  do one of: {remedies}; or --accept-error to write it as it is")


def stages_label(look: nn.Module) -> str:
    """The stage classes of ``look`` in order, ``"A -> B"``, for the one line each subcommand prints."""
    return " -> ".join(type(stage).__name__ for stage in look.children())


def grade_from_args(args: argparse.Namespace) -> nn.Sequential:
    """``ColorGrade`` (in ACES when tone mapping with ``aces``) and ``ToneMap`` from the grading flags.

    Examples:
        >>> args = argparse.Namespace(tonemap="neutral", post_exposure=None, temperature=None, tint=None,
        ...                           contrast=20.0, hue_shift=None, saturation=None)
        >>> grade, tonemap = grade_from_args(args)
        >>> grade.to_config(), tonemap.mode
        ({'contrast': 20.0}, 'neutral')
    """
    controls = {name: getattr(args, name) for name in GRADING_FLAGS if getattr(args, name) is not None}
    tonemap = args.tonemap or "aces"
    return nn.Sequential(ColorGrade(aces=tonemap == "aces", **controls), ToneMap(tonemap))


def given_grading_flags(args: argparse.Namespace) -> list:
    """The grading flags set on the command line, as the user typed them (``--contrast``).

    Examples:
        >>> args = argparse.Namespace(tonemap=None, post_exposure=0.5, temperature=None, tint=None,
        ...                           contrast=None, hue_shift=None, saturation=None)
        >>> given_grading_flags(args)
        ['--post-exposure']
    """
    return ["--" + name.replace("_", "-") for name in (*GRADING_FLAGS, "tonemap") if getattr(args, name) is not None]


def given_exposure_flags(args: argparse.Namespace) -> list:
    """The eye-adaptation flags set on the command line (none where the subcommand has none).

    Examples:
        >>> given_exposure_flags(argparse.Namespace(metering="histogram", ev_limits=None)), given_exposure_flags(argparse.Namespace())
        (['--metering'], [])
    """
    return ["--" + name.replace("_", "-") for name in EXPOSURE_FLAGS if getattr(args, name, None) is not None]


def exposure_from_args(args: argparse.Namespace) -> dict | None:
    """The ``AutoExposure`` config the eye-adaptation flags ask for, ``None`` without any; ``ValueError`` for
    ``--histogram-percent`` without histogram metering, where it would change nothing (``AutoExposure`` then refuses
    a band whose low end is not below its high end).

    Examples:
        >>> args = argparse.Namespace(metering="histogram", metering_mask="center", compensation=None, ev_limits=[-3.0, 3.0],
        ...                           fixed_exposure=None, histogram_percent=None)
        >>> exposure_from_args(args)
        {'metering': 'histogram', 'metering_mask': 'center', 'min_ev': -3.0, 'max_ev': 3.0}
    """
    if not given_exposure_flags(args):
        return None
    config = {name: getattr(args, name) for name in ("metering", "metering_mask", "compensation", "fixed_exposure")
              if getattr(args, name) is not None}
    if args.ev_limits is not None:
        config["min_ev"], config["max_ev"] = args.ev_limits
    if args.histogram_percent is not None:
        if args.metering != "histogram":
            raise ValueError("--histogram-percent is the band histogram metering averages: give it with --metering histogram")
        config["low_percent"], config["high_percent"] = args.histogram_percent
    return config


def add_exposure_flags(parser: argparse.ArgumentParser) -> None:
    """One flag per :data:`EXPOSURE_FLAGS` control.

    Examples:
        >>> parser = argparse.ArgumentParser()
        >>> add_exposure_flags(parser)
        >>> parser.parse_args(["--metering", "histogram", "--ev-limits", "-4", "2"]).ev_limits
        [-4.0, 2.0]
    """
    from ..exposure import METERING_MASKS, METERING_MODES

    flags = parser.add_argument_group("eye adaptation (adds an AutoExposure stage)")
    flags.add_argument("--metering", choices=METERING_MODES, help=EXPOSURE_FLAGS["metering"])
    flags.add_argument("--metering-mask", choices=METERING_MASKS, help=EXPOSURE_FLAGS["metering_mask"])
    flags.add_argument("--histogram-percent", type=float, nargs=2, metavar=("LOW", "HIGH"), help=EXPOSURE_FLAGS["histogram_percent"])
    flags.add_argument("--compensation", type=float, help=EXPOSURE_FLAGS["compensation"])
    flags.add_argument("--ev-limits", type=float, nargs=2, metavar=("MIN", "MAX"), help=EXPOSURE_FLAGS["ev_limits"])
    flags.add_argument("--fixed-exposure", type=float, metavar="STOPS", help=EXPOSURE_FLAGS["fixed_exposure"])


def look_from_args(args: argparse.Namespace) -> PostFX:
    """The look a subcommand applies: from ``--config``, or from the grading and eye-adaptation flags.

    Examples:
        >>> args = argparse.Namespace(config=None, tonemap=None, post_exposure=None, temperature=None, tint=None,
        ...                           contrast=None, hue_shift=None, saturation=10.0)
        >>> look_from_args(args).to_config()
        {'grade': {'aces': True, 'saturation': 10.0}, 'tonemap': {'mode': 'aces'}}
    """
    if args.config is None:
        grade, tonemap = grade_from_args(args)
        return PostFX(exposure=exposure_from_args(args), grade=grade, tonemap=tonemap)
    given = given_grading_flags(args) + given_exposure_flags(args)
    if given:
        raise ValueError(f"give --config or grading flags, not both (got --config and {', '.join(given)})")
    return PostFX.from_config(args.config)


def add_grading_flags(parser: argparse.ArgumentParser) -> None:
    """``--tonemap`` and one flag per :data:`GRADING_FLAGS` control.

    Examples:
        >>> parser = argparse.ArgumentParser()
        >>> add_grading_flags(parser)
        >>> parser.parse_args(["--hue-shift", "-30", "--tonemap", "agx"]).hue_shift
        -30.0
    """
    parser.add_argument("--tonemap", choices=TONEMAP_MODES, help="default aces")
    for name, unit in GRADING_FLAGS.items():
        parser.add_argument("--" + name.replace("_", "-"), type=float, help=unit)
