"""Decoding an untrusted OpenEXR file: budget checked from the headers first, library errors fatal.

The bindings decode every channel of every part at once, and report some damage (a corrupt chunk
table, a chunk that fails to decompress) only by printing to the process's standard error and
leaving the damaged part out or partly filled. So the budget counts everything the bindings will
decode, and whatever the library prints while decoding (to stdout or stderr) turns into a
``ValueError``. The redirection is process-wide: output other threads write meanwhile is
swallowed with it, and reads in several threads decode one at a time.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading

import OpenEXR

from .layout import ExrPart

__all__ = ["MAX_BYTES", "MAX_PIXELS", "check_budget", "decode"]

MAX_PIXELS = 1 << 28
"""Largest window (268 megapixels) read_exr accepts by default."""

MAX_BYTES = 1 << 31
"""Default bound (2 GiB) on the memory a read may take: every sample the bindings decode (2 bytes
half, 4 float), plus the float32 tensor returned."""


def check_budget(path, parts: list[ExrPart], chosen: ExrPart, window: str, output_channels: int, max_pixels: int,
                 max_bytes: int) -> None:
    """Raise ``ValueError`` naming the numbers when decoding ``parts`` and returning ``chosen`` would pass either bound.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> from torchgrade.io import exr_info
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 64, 64))
        >>> parts = exr_info(path)
        >>> check_budget(path, parts, parts[0], "data", 3, max_pixels=1 << 20, max_bytes=1000)
        Traceback (most recent call last):
        ValueError: ...rgb.exr: reading needs about 73728 bytes (24576 decoded + 49152 returned), above the budget of 1000 bytes (max_bytes)
    """
    for part in parts:
        if part.deep:
            raise ValueError(f"{path}: part {part.index} holds deep data ({part.kind}), which read_exr does not read; "
                             "flatten it first (e.g. with OpenImageIO's oiiotool --flatten)")
        height, width = part.size()
        if height <= 0 or width <= 0 or height * width > max_pixels:
            raise ValueError(f"{path}: part {part.index} data window {width}x{height} is empty or above the "
                             f"budget of {max_pixels} pixels (max_pixels)")
    decoded = sum(_decoded_bytes(part) for part in parts)
    height, width = chosen.size(window)
    if height <= 0 or width <= 0 or height * width > max_pixels:
        raise ValueError(f"{path}: {window} window {width}x{height} is empty or above the budget of {max_pixels} pixels (max_pixels)")
    returned = 4 * output_channels * height * width
    if decoded + returned > max_bytes:
        raise ValueError(f"{path}: reading needs about {decoded + returned} bytes ({decoded} decoded + {returned} returned), "
                         f"above the budget of {max_bytes} bytes (max_bytes)")


def _decoded_bytes(part: ExrPart) -> int:
    height, width = part.size()
    return sum(part.sample_bytes[name] * -(-height // ys) * -(-width // xs) for name, (xs, ys) in part.channels.items())


_REDIRECTING = threading.Lock()
"""Held while file descriptors 1 and 2 point elsewhere: two threads redirecting at once would
restore each other's redirection instead of the real stdout and stderr."""


@contextlib.contextmanager
def _captured_output():
    """Collect what native code writes to file descriptors 1 and 2 (stdout, stderr) meanwhile."""
    with _REDIRECTING, tempfile.TemporaryFile() as sink:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
        os.dup2(sink.fileno(), 1)
        os.dup2(sink.fileno(), 2)
        messages = []
        try:
            yield messages
        finally:
            for descriptor, copy in enumerate(saved, start=1):
                os.dup2(copy, descriptor)
                os.close(copy)
            sink.seek(0)
            messages.extend(sink.read().decode("utf-8", "replace").splitlines())


def decode(path, parts: list[ExrPart]):
    """Every part's channels as ``{name: numpy array}`` dicts, one per part, or ``ValueError``.

    The library's own complaints (printed while decoding) and any part or channel missing from the
    result reject the file; a ``MemoryError`` becomes a ``ValueError`` too.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> from torchgrade.io import exr_info
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 4))
        >>> {name: array.shape for name, array in decode(path, exr_info(path))[0].items()}
        {'B': (2, 4), 'G': (2, 4), 'R': (2, 4)}
    """
    try:
        with _captured_output() as messages:
            opened = OpenEXR.File(str(path), separate_channels=True)
            decoded = [{name: channel.pixels for name, channel in part.channels.items()} for part in opened.parts]
    except MemoryError:
        raise ValueError(f"{path}: not enough memory to decode the pixels (use a smaller max_bytes)") from None
    except Exception as error:
        raise ValueError(f"{path}: cannot decode OpenEXR pixels ({error})") from None
    if messages:
        raise ValueError(f"{path}: damaged OpenEXR file ({messages[0].replace(str(path) + ': ', '')})")
    if len(decoded) != len(parts) or any(set(d) != set(p.channels) for d, p in zip(decoded, parts)):
        raise ValueError(f"{path}: damaged OpenEXR file (the library returned fewer parts or channels than the header lists)")
    return decoded
