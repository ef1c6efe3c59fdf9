"""The raw header bytes of an OpenEXR file: where each attribute lies, the attributes a header must
hold, each channel's sample size and the tile size.

The bindings' header-only mode gives the attributes' values but neither the channels' pixel types
(HALF, FLOAT or UINT, which the byte budget needs) nor where the headers lie in the file (which
:mod:`torchgrade.io.exr.single_part` and :mod:`torchgrade.io.exr.chunks` need), and where a header
lacks an attribute the format requires it stands in a default (a 64x64 ``dataWindow``) instead of
refusing the file. So the headers are also read here, directly, as OpenEXR's file layout document
describes them (https://openexr.com/en/latest/OpenEXRFileLayout.html): after the 4-byte magic number
and 4-byte version field, each header is a run of attributes (name, type name, 4-byte size, value)
ended by a zero byte, and a multi-part file (version bit 12) ends its headers with one more zero
byte; the offset tables follow. A ``chlist`` value is a run of channels (name, 4-byte pixel type,
1-byte pLinear, 3 reserved bytes, 4-byte x and y sampling) ended by a zero byte; a ``tiledesc`` is
the tile width and height (4 bytes each) and a byte of level and rounding modes.
"""

from __future__ import annotations

import mmap
import struct
from dataclasses import dataclass

__all__ = ["MAGIC", "MULTIPART", "MAX_ATTRIBUTES", "MAX_FILE_ATTRIBUTES", "MAX_CHANNELS", "MAX_FILE_CHANNELS", "MAX_PARTS",
           "MAX_HEADER_BYTES", "HeaderBudgetError", "Attribute", "Headers", "PartBytes", "channel_list", "check_headers",
           "check_required", "part_bytes", "read_headers", "value"]

MAGIC = 20000630
"""The first four bytes of every OpenEXR file, as a little-endian int."""

_BYTES = {0: 4, 1: 2, 2: 4}
"""Bytes per sample of OpenEXR's UINT, HALF and FLOAT pixel types."""

MULTIPART = 1 << 12
"""The version field's multi-part bit."""

MAX_ATTRIBUTES = 1024
"""Most attributes a header may hold (the sample files hold at most 40): OpenEXR's own header parser takes time that
grows with the square of their number (200,000 empty ones, 3 MB, took 198 s), so more are refused before it runs."""

MAX_FILE_ATTRIBUTES = 16384
"""Most attributes all the headers of a file may hold together (the required ones of 1,024 parts are 11,264): OpenEXR's
parser pays for every part's, and 1,024 parts of 1,000 attributes (14 MB) held it for tens of seconds and a GiB
for an 8x4 image."""

MAX_CHANNELS = 4096
"""Most channels a part may hold (a render's AOVs are a few hundred): OpenEXR's header parser takes time that grows with
the square of their number (100,003 held it for tens of seconds)."""

MAX_FILE_CHANNELS = 16384
"""Most channels all the parts of a file may hold together."""

MAX_PARTS = 1024
"""Most parts a file may hold."""

MAX_HEADER_BYTES = 16 << 20
"""Most bytes the headers may span, to the end of their last attribute (a 2048x2048 preview image fits, and a
thumbnail and an ICC profile many times over): OpenEXR's parser holds about four times the headers' bytes (one
attribute of 70 MB held 280 MiB for an 8x4 image), and tests/io/test_doors.py holds headers of this size under 100 MB."""
_TILED, _DEEP = 1 << 9, 1 << 11
"""The version field's single-part tiled bit and its non-image (deep data) bit."""

_FORMATS = {"box2i": "<4i", "compression": "<B", "float": "<f", "int": "<i", "lineOrder": "<B", "tiledesc": "<IIB",
            "v2f": "<2f"}
"""``struct`` formats of the fixed-size attribute types this module reads or requires."""

_REQUIRED = {"channels": "chlist", "compression": "compression", "dataWindow": "box2i", "displayWindow": "box2i",
             "lineOrder": "lineOrder", "pixelAspectRatio": "float", "screenWindowCenter": "v2f", "screenWindowWidth": "float"}
"""The attributes every header holds, with their types (file layout document, "Header Attributes (All Files)")."""
_REQUIRED_TILED = {"tiles": "tiledesc"}
_REQUIRED_PARTS = {"name": "string", "type": "string", "chunkCount": "int"}
"""What a tiled part's header holds too, and each header of a multi-part or deep file (file layout
document, "Tile Header Attribute" and "Multi-Part and Deep Data Header Attributes")."""


class HeaderBudgetError(ValueError):
    """Headers past one of the budgets (:data:`MAX_ATTRIBUTES`, :data:`MAX_FILE_ATTRIBUTES`, :data:`MAX_CHANNELS`,
    :data:`MAX_FILE_CHANNELS`, :data:`MAX_PARTS`, :data:`MAX_HEADER_BYTES`): refused before OpenEXR's own parser sees
    them, whatever else a caller tolerates in a damaged header."""


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

    def attributes(self, index: int) -> dict[str, Attribute]:
        """Part ``index``'s attributes by name."""
        return {attribute.name: attribute for attribute in self.parts[index]}


@dataclass(frozen=True)
class PartBytes:
    """What a part's header bytes say that the budget needs: each channel's sample size (2 half, 4
    float or uint), which the bindings' header-only mode does not give, and the tile ``(width, height)``
    of its ``tiles`` attribute (``None`` without one), which must be known before they read it."""

    sample_bytes: dict[str, int]
    tile_size: tuple[int, int] | None


def _name(data, at: int) -> tuple[str, int]:
    end = data.find(b"\0", at, at + 256)  # names are at most 255 bytes
    if end < 0:
        raise ValueError("unterminated name")
    return data[at:end].decode("utf-8", "replace"), end + 1  # as the bindings decode names


def channel_list(data, attribute: Attribute) -> dict[str, int]:
    """``{channel: bytes a sample}`` of a ``chlist`` attribute, at most :data:`MAX_CHANNELS` of them, each named once
    (OpenEXR refuses a name listed twice too; refused here, every entry is a channel the budgets count)."""
    at, end = attribute.value, attribute.end
    channels: dict[str, int] = {}
    while at < end and data[at] != 0:
        if len(channels) == MAX_CHANNELS:
            raise HeaderBudgetError(f"a part holds more than {MAX_CHANNELS} channels")
        name, at = _name(data, at)
        if name in channels:
            raise ValueError(f"channel {name!r} is listed twice")
        (pixel_type,) = struct.unpack_from("<i", data, at)
        if pixel_type not in _BYTES:
            raise ValueError(f"channel {name!r} has pixel type {pixel_type}, not 0 (uint), 1 (half) or 2 (float)")
        channels[name] = _BYTES[pixel_type]
        at += 16
    return channels


def _attributes(data, at: int, before: int) -> tuple[list[Attribute], int]:
    """The attributes of the header at ``at``, and where it ends; ``before`` the earlier headers hold."""
    attributes: list[Attribute] = []
    while data[at] != 0:
        if len(attributes) == MAX_ATTRIBUTES:
            raise HeaderBudgetError(f"a header holds more than {MAX_ATTRIBUTES} attributes")
        if before + len(attributes) == MAX_FILE_ATTRIBUTES:
            raise HeaderBudgetError(f"the headers hold more than {MAX_FILE_ATTRIBUTES} attributes in all")
        start = at
        name, at = _name(data, at)
        kind, at = _name(data, at)
        (size,) = struct.unpack_from("<i", data, at)
        if at + 4 + size > MAX_HEADER_BYTES:
            raise HeaderBudgetError(f"the headers span more than {MAX_HEADER_BYTES} bytes")
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
    magic, version = struct.unpack_from("<ii", data)
    if magic != MAGIC:
        raise ValueError(f"no OpenEXR magic number (the file starts with {bytes(data[:4])!r})")
    parts: list[list[Attribute]] = []
    at, count = 8, 0
    while True:
        if len(parts) == MAX_PARTS:
            raise HeaderBudgetError(f"the file holds more than {MAX_PARTS} parts")
        attributes, at = _attributes(data, at, count)
        count += len(attributes)
        parts.append(attributes)
        if not version & MULTIPART or data[at] == 0:
            break
    return Headers(version, parts, at + 1 if version & MULTIPART else at)


def value(data, attribute: Attribute):
    """The value of an attribute of a type in ``_FORMATS`` (a tuple, as ``struct`` unpacks it), or of a
    ``string`` (its text)."""
    if attribute.kind == "string":
        return data[attribute.value:attribute.end].decode("utf-8", "replace")
    return struct.unpack_from(_FORMATS[attribute.kind], data, attribute.value)


def _required(headers: Headers, data, index: int) -> dict[str, str]:
    """The attributes part ``index`` must hold: a part is tiled by the version field's bit 9 in a
    single-part file, by its ``type`` in a multi-part or deep one."""
    attributes = headers.attributes(index)
    required = dict(_REQUIRED)
    if headers.version & (MULTIPART | _DEEP):
        required.update(_REQUIRED_PARTS)
        kind = attributes.get("type")
        tiled = kind is not None and kind.kind == "string" and value(data, kind) in ("tiledimage", "deeptile")
    else:
        tiled = bool(headers.version & _TILED)
    return {**required, **_REQUIRED_TILED} if tiled else required


def check_required(headers: Headers, data) -> None:
    """``ValueError`` naming the first attribute the format requires (see ``_REQUIRED``) that a header
    lacks, or holds with another type or size than the format gives it.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "half.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 2))
        >>> data = bytearray(path.read_bytes())
        >>> check_required(read_headers(data), data)
        >>> data[data.index(b"dataWindow")] = ord("x")
        >>> check_required(read_headers(data), data)
        Traceback (most recent call last):
        ValueError: part 0 lacks the required attribute dataWindow (box2i)
    """
    for index in range(len(headers.parts)):
        attributes = headers.attributes(index)
        for name, kind in _required(headers, data, index).items():
            found = attributes.get(name)
            size = struct.calcsize(_FORMATS[kind]) if kind in _FORMATS else None
            if found is None:
                raise ValueError(f"part {index} lacks the required attribute {name} ({kind})")
            if found.kind != kind or size not in (None, found.end - found.value):
                raise ValueError(f"part {index} lacks the required attribute {name} ({kind}{f', {size} bytes' if size else ''}): "
                                 f"its {name} is a {found.kind} of {found.end - found.value} bytes")


def check_headers(path) -> None:
    """``ValueError`` naming the file at ``path`` when its headers do not parse, or one lacks an attribute
    the format requires (``check_required``).

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "half.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 2))
        >>> _ = path.write_bytes(path.read_bytes().replace(b"lineOrder", b"lineOrdeR"))
        >>> check_headers(path)
        Traceback (most recent call last):
        ValueError: ...half.exr: not a readable OpenEXR file (part 0 lacks the required attribute lineOrder (lineOrder))
    """
    try:
        with open(path, "rb") as file, mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            check_required(read_headers(data), data)
    except (ValueError, IndexError, struct.error) as error:  # mmap refuses an empty file with ValueError
        raise ValueError(f"{path}: not a readable OpenEXR file ({error})") from None


def part_bytes(path) -> list[PartBytes] | None:
    """``PartBytes`` of each part of the file at ``path``, or ``None`` when its headers do not parse.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "half.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 2))
        >>> part_bytes(path)
        [PartBytes(sample_bytes={'B': 2, 'G': 2, 'R': 2}, tile_size=None)]
    """
    try:
        with open(path, "rb") as file, mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            headers = read_headers(data)
            parts, channel_count = [], 0
            for index in range(len(headers.parts)):
                attributes = headers.attributes(index)
                channels, tiles = attributes.get("channels"), attributes.get("tiles")
                parts.append(PartBytes(channel_list(data, channels) if channels else {},
                                       value(data, tiles)[:2] if tiles is not None and tiles.kind == "tiledesc" else None))
                channel_count += len(parts[-1].sample_bytes)
                if channel_count > MAX_FILE_CHANNELS:
                    raise HeaderBudgetError(f"the parts hold more than {MAX_FILE_CHANNELS} channels in all")
            return parts
    except HeaderBudgetError:
        raise
    except (OSError, ValueError, IndexError, struct.error):  # mmap refuses an empty file with ValueError
        return None
