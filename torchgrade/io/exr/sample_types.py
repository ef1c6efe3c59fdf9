"""Bytes per sample of every channel, read from the raw header bytes.

The bindings' header-only mode names each channel and its sampling but not its pixel type (HALF,
FLOAT or UINT), which the byte budget needs. The channel lists are short and sit at the start of
the file, so they are read here directly, as OpenEXR's file layout document describes them: after
the 4-byte magic number and 4-byte version, each header is a run of attributes (name, type name,
4-byte size, value) ended by a zero byte, and a multi-part file (version bit 12) ends its headers
with one more zero byte. A ``chlist`` value is a run of channels (name, 4-byte pixel type, 1-byte
pLinear, 3 reserved bytes, 4-byte x and y sampling) ended by a zero byte.
"""

from __future__ import annotations

import mmap
import struct

__all__ = ["sample_bytes"]

_BYTES = {0: 4, 1: 2, 2: 4}
"""Bytes per sample of OpenEXR's UINT, HALF and FLOAT pixel types."""

_MULTIPART = 1 << 12


def _name(data, at: int) -> tuple[str, int]:
    end = data.find(b"\0", at, at + 256)  # names are at most 255 bytes
    if end < 0:
        raise ValueError("unterminated name")
    return data[at:end].decode("ascii", "replace"), end + 1


def _channel_list(data, at: int, end: int) -> dict[str, int]:
    channels = {}
    while at < end and data[at] != 0:
        name, at = _name(data, at)
        (pixel_type,) = struct.unpack_from("<i", data, at)
        channels[name] = _BYTES[pixel_type]
        at += 16
    return channels


def _headers(data) -> list[dict[str, int]]:
    (version,) = struct.unpack_from("<i", data, 4)
    at, parts = 8, []
    while data[at] != 0:
        channels = {}
        while data[at] != 0:
            name, at = _name(data, at)
            kind, at = _name(data, at)
            (size,) = struct.unpack_from("<i", data, at)
            if size < 0:
                raise ValueError("negative attribute size")
            if (name, kind) == ("channels", "chlist"):
                channels = _channel_list(data, at + 4, at + 4 + size)
            at += 4 + size
        parts.append(channels)
        at += 1
        if not version & _MULTIPART:
            break
    return parts


def sample_bytes(path) -> list[dict[str, int]] | None:
    """``[{channel: 2 or 4}]``, one dict per part, or ``None`` when the header bytes do not parse.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "half.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 2))
        >>> sample_bytes(path)
        [{'B': 2, 'G': 2, 'R': 2}]
    """
    try:
        with open(path, "rb") as file, mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _headers(data)
    except (OSError, ValueError, KeyError, IndexError, struct.error):
        return None
