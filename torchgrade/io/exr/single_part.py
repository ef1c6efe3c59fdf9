"""One part of a multi-part OpenEXR file, copied out as a single-part file so that it decodes alone.

The OpenEXR 3.5 Python bindings decode no part on its own: ``OpenEXR.File`` decodes every channel of
every part, and the deprecated ``OpenEXR.InputFile``, the one call that decodes chosen channels,
only reaches the first part. So a later part is rewritten, still compressed, as the single-part file
it would have been, following OpenEXR's file layout document
(https://openexr.com/en/latest/OpenEXRFileLayout.html):

- the magic number, then the version field without the multi-part bit, with the single-part tiled
  bit (9) for a tiled part and the long-names bit (10) as the file had it;
- the part's header attributes as they are (``name``, ``type`` and ``chunkCount`` included: a
  single-part reader ignores the first two, and checks the third against the chunk count it computes
  from the header, printing a complaint that rejects the file when they differ), ended by a zero byte;
- a new offset table, then the part's chunks, each without the leading part number that multi-part
  chunks carry (a scanline chunk: y, size, data; a tile: four coordinates, size, data).

The chunks are copied one at a time, in pieces of at most 1 MiB, so the copy never holds the part in
memory. A chunk table that points outside the file or at another part's chunk, or a chunk that runs
past the end of the file, rejects the file with a ``ValueError`` naming it.
"""

from __future__ import annotations

import mmap
import os
import struct

import numpy as np

from .header_bytes import MULTIPART, read_headers
from .layout import ExrPart

__all__ = ["write_single_part"]

_MAGIC = 20000630
_TILED = 1 << 9
_LONG_NAMES = 1 << 10
_PIECE = 1 << 20
"""Bytes copied at a time."""
_TABLE_ENTRIES = 1 << 13
"""Offsets read and written at a time (64 KiB)."""


def _chunk_counts(path, data, headers) -> list[int]:
    counts = []
    for index, attributes in enumerate(headers.parts):
        found = [a for a in attributes if a.name == "chunkCount" and a.kind == "int" and a.end - a.value == 4]
        if len(found) != 1:
            raise ValueError(f"{path}: damaged OpenEXR file (part {index} has no chunkCount, which a multi-part file needs)")
        (count,) = struct.unpack_from("<i", data, found[0].value)
        if count < 0:
            raise ValueError(f"{path}: damaged OpenEXR file (part {index} has a chunkCount of {count})")
        counts.append(count)
    return counts


def _copy(source: int, at: int, size: int, target) -> None:
    """Bytes ``at``..``at + size`` of the file ``source`` (a descriptor) appended to ``target``."""
    while size > 0:
        piece = os.pread(source, min(size, _PIECE), at)
        if not piece:
            raise EOFError
        target.write(piece)
        at, size = at + len(piece), size - len(piece)


def _copy_chunks(path, source: int, file_size: int, table: int, chunks: int, count: int, index: int, tiled: bool,
                 target) -> None:
    """Copy part ``index``'s ``count`` chunks, whose offsets are at ``table`` in ``source`` (a descriptor)
    and whose chunks lie from ``chunks`` on, to ``target``: the new offset table from ``target``'s
    current position, the chunks after it."""
    coordinates = 4 * (4 if tiled else 1)
    new_table = target.tell()
    at = new_table + 8 * count
    target.seek(at)
    for block in range(0, count, _TABLE_ENTRIES):
        entries = min(_TABLE_ENTRIES, count - block)
        offsets = np.frombuffer(os.pread(source, 8 * entries, table + 8 * block), "<u8")
        if len(offsets) != entries:
            raise ValueError(f"{path}: damaged OpenEXR file (part {index}'s offset table runs past the end of the file)")
        new_offsets = np.empty(entries, "<u8")
        for number, offset in enumerate(offsets.tolist()):
            chunk = block + number
            head = os.pread(source, 4 + coordinates + 4, offset) if chunks <= offset < file_size else b""
            if len(head) != 4 + coordinates + 4:
                raise ValueError(f"{path}: damaged OpenEXR file (part {index} chunk {chunk} at offset {offset}, outside the "
                                 f"chunks of a file of {file_size} bytes)")
            owner, size = struct.unpack_from("<i", head)[0], struct.unpack_from("<i", head, 4 + coordinates)[0]
            if owner != index:
                raise ValueError(f"{path}: damaged OpenEXR file (part {index} chunk {chunk} at offset {offset} belongs to part {owner})")
            if size < 0 or offset + len(head) + size > file_size:
                raise ValueError(f"{path}: damaged OpenEXR file (part {index} chunk {chunk} of {size} bytes at offset {offset} "
                                 f"runs past the end of the file of {file_size} bytes)")
            new_offsets[number] = at
            target.write(head[4:])
            _copy(source, offset + len(head), size, target)
            at += len(head) - 4 + size
        target.seek(new_table + 8 * block)
        target.write(new_offsets.tobytes())
        target.seek(at)


def _headers(path, descriptor: int):
    """The file's headers, its chunk counts, and the bytes of its headers."""
    with mmap.mmap(descriptor, 0, access=mmap.ACCESS_READ) as data:
        try:
            headers = read_headers(data)
        except (ValueError, IndexError, struct.error) as error:
            raise ValueError(f"{path}: not a readable OpenEXR file ({error})") from None
        return headers, _chunk_counts(path, data, headers), [[data[a.start:a.end] for a in part] for part in headers.parts]


def write_single_part(path, chosen: ExrPart, target) -> None:
    """Write part ``chosen`` of the multi-part file ``path`` to the binary file object ``target`` as a
    single-part OpenEXR file, or raise ``ValueError`` naming ``path``.

    Examples:
        >>> import pathlib, tempfile, numpy as np, OpenEXR
        >>> from torchgrade.io import exr_info
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "parts.exr"
        >>> planes = [{"Y": np.full((2, 3), value, np.float16)} for value in (1, 2)]
        >>> OpenEXR.File([OpenEXR.Part({"name": f"p{value}"}, p) for value, p in zip((1, 2), planes)]).write(str(path))
        >>> copy = path.with_name("part1.exr")
        >>> with open(copy, "wb") as target:
        ...     write_single_part(path, exr_info(path)[1], target)
        >>> OpenEXR.File(str(copy)).parts[0].channels["Y"].pixels.tolist()
        [[2.0, 2.0, 2.0], [2.0, 2.0, 2.0]]
    """
    descriptor = os.open(path, os.O_RDONLY)
    try:
        headers, counts, attributes = _headers(path, descriptor)
        if not headers.version & MULTIPART or chosen.index >= len(headers.parts):
            raise ValueError(f"{path}: no part {chosen.index} among the file's {len(headers.parts)}")
        tiled = chosen.kind == "tiledimage"
        version = (headers.version & 0xFF) | (headers.version & _LONG_NAMES) | (_TILED if tiled else 0)
        target.write(struct.pack("<ii", _MAGIC, version) + b"".join(attributes[chosen.index]) + b"\0")
        table, chunks = headers.end + 8 * sum(counts[:chosen.index]), headers.end + 8 * sum(counts)
        _copy_chunks(path, descriptor, os.fstat(descriptor).st_size, table, chunks, counts[chosen.index], chosen.index, tiled,
                     target)
    finally:
        os.close(descriptor)
