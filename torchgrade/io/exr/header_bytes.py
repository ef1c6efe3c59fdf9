"""The raw header bytes of an OpenEXR file: where each attribute lies, and each channel's sample size.

The bindings' header-only mode gives the attributes' values but neither the channels' pixel types
(HALF, FLOAT or UINT, which the byte budget needs) nor where the headers lie in the file (which
:mod:`torchgrade.io.exr.single_part` needs to copy one part out). Both are read here directly, as
OpenEXR's file layout document describes them (https://openexr.com/en/latest/OpenEXRFileLayout.html):
after the 4-byte magic number and 4-byte version field, each header is a run of attributes (name,
type name, 4-byte size, value) ended by a zero byte, and a multi-part file (version bit 12) ends its
headers with one more zero byte; the offset tables follow. A ``chlist`` value is a run of channels
(name, 4-byte pixel type, 1-byte pLinear, 3 reserved bytes, 4-byte x and y sampling) ended by a
zero byte.
"""

from __future__ import annotations

import mmap
import struct
from dataclasses import dataclass

__all__ = ["MULTIPART", "Attribute", "Headers", "read_headers", "sample_bytes"]

_BYTES = {0: 4, 1: 2, 2: 4}
"""Bytes per sample of OpenEXR's UINT, HALF and FLOAT pixel types."""

MULTIPART = 1 << 12
"""The version field's multi-part bit."""


@dataclass(frozen=True)
class Attribute:
    """One header attribute: its name, type name, and the bytes ``start``..``end`` it spans in the
    file, its value from ``value`` on."""

    name: str
    kind: str
    start: int
    value: int
    end: int


@dataclass(frozen=True)
class Headers:
    """The version field, each part's attributes in file order, and where the offset tables start."""

    version: int
    parts: list[list[Attribute]]
    end: int


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


def _attributes(data, at: int) -> tuple[list[Attribute], int]:
    attributes = []
    while data[at] != 0:
        start = at
        name, at = _name(data, at)
        kind, at = _name(data, at)
        (size,) = struct.unpack_from("<i", data, at)
        if size < 0 or at + 4 + size > len(data):
            raise ValueError(f"attribute {name!r} of {size} bytes does not fit in the file")
        attributes.append(Attribute(name, kind, start, at + 4, at + 4 + size))
        at += 4 + size
    return attributes, at + 1


def read_headers(data) -> Headers:
    """Every header of the file whose bytes are ``data``; ``ValueError`` (or ``IndexError``,
    ``struct.error``) when they do not parse.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "half.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 2))
        >>> headers = read_headers(path.read_bytes())
        >>> headers.version, [attribute.name for attribute in headers.parts[0]][:3]
        (2, ['channels', 'compression', 'dataWindow'])
    """
    (version,) = struct.unpack_from("<i", data, 4)
    parts, at = [], 8
    while True:
        attributes, at = _attributes(data, at)
        parts.append(attributes)
        if not version & MULTIPART or data[at] == 0:
            break
    return Headers(version, parts, at + 1 if version & MULTIPART else at)


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
            return [next((_channel_list(data, a.value, a.end) for a in part if (a.name, a.kind) == ("channels", "chlist")), {})
                    for part in read_headers(data).parts]
    except (OSError, ValueError, KeyError, IndexError, struct.error):
        return None
