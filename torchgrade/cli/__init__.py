"""The ``torchgrade`` command: ``demo`` renders the built-in scene, ``grade`` grades an EXR file,
``bake`` writes a look's grade and tone mapping as a ``.cube`` 3D LUT, ``export`` writes a look as ONNX and
verifies it on onnxruntime, ``match`` learns a look from a before/after pair. One module per subcommand, each adding its own parser.

Examples:
    >>> main(["grade", "missing.exr", "-o", "out.png"])  # one line on stderr, status 2
    2
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading

from .. import __version__
from .bake import add_bake
from .common import OVER_TOLERANCE, LUTOverTolerance
from .demo import add_demo
from .export import add_export
from .grade import add_grade
from .match import add_match

__all__ = ["main"]

TERMINATED = 128 + signal.SIGTERM
"""The exit status of a command stopped by SIGTERM, as a shell reports it."""

INTERRUPTED = 128 + signal.SIGINT
"""The exit status of a command stopped by Ctrl-C (SIGINT), as a shell reports it."""

SUBCOMMANDS = (add_demo, add_grade, add_bake, add_export, add_match)
"""Each subcommand's parser builder, in the order ``--help`` lists them."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="torchgrade", description="Differentiable HDR post-processing.")
    parser.add_argument("--version", action="version", version=f"torchgrade {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    for add in SUBCOMMANDS:
        add(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv``; a bad input prints one line on stderr and returns 2, never a traceback; a LUT
    baked past its tolerance (``bake``, ``export --lut``) prints its report and what to do, and returns
    :data:`~torchgrade.cli.common.OVER_TOLERANCE` (3) unless ``--accept-error`` is given; Ctrl-C prints one line and
    returns :data:`INTERRUPTED` (130), every write in flight having removed its temporary file.

    Examples:
        >>> main(["bake", "-o", "look.txt"])  # stderr: torchgrade bake: error: output must end in .cube, got look.txt
        2
    """
    args = _parser().parse_args(argv)
    try:
        with _terminated_as_an_exit():
            print(args.run(args))
    except (ValueError, TypeError, OSError) as error:
        print(f"torchgrade {args.command}: error: {error}", file=sys.stderr)
        return 2
    except LUTOverTolerance as error:
        print(f"torchgrade {args.command}: error: {error}", file=sys.stderr)
        return OVER_TOLERANCE
    except KeyboardInterrupt:
        print(f"torchgrade {args.command}: interrupted", file=sys.stderr)
        return INTERRUPTED
    return 0


@contextlib.contextmanager
def _terminated_as_an_exit():
    """SIGTERM (a ``kill``, a scheduler's stop) ends the command as an exception does, so that every write in flight
    removes its temporary file (:func:`torchgrade.io.atomic.atomic_write`) before the process ends with
    :data:`TERMINATED`; SIGINT (Ctrl-C) does so already. Only in the main thread, where Python delivers signals."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(number, frame):
        raise SystemExit(TERMINATED)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
