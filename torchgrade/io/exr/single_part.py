"""One part of a multi-part OpenEXR file, copied out as a single-part file so that it decodes alone.

The OpenEXR 3.5 Python bindings decode no part on its own: ``OpenEXR.File`` decodes every channel of
every part, and the deprecated ``OpenEXR.InputFile``, the one call that decodes chosen channels,
only reaches the first part. So a later part is rewritten, still compressed, as the single-part file
it would have been, following OpenEXR's file layout document
(https://openexr.com/en/latest/OpenEXRFileLayout.html):

- the magic number, then the version field without the multi-part bit, with the single-part tiled
  bit (9) for a tiled part and the long-names bit (10) as the file had it;
- the part's header attributes as they are (``name``, ``type`` and ``chunkCount`` included: a
  single-part reader ignores the first two, and the third is the chunk count its header gives, as
  the table check made sure), ended by a zero byte;
- a new offset table, then the part's chunks, each without the leading part number that multi-part
  chunks carry (a scanline chunk: y, size, data; a tile: four coordinates, size, data).

The chunks are found through the part's checked offset table (:func:`torchgrade.io.exr.chunks.chunk_table`)
and copied one at a time, in pieces of at most 1 MiB, so the copy never holds the part in memory.
"""

from __future__ import annotations

import mmap
import os
import struct

import numpy as np

from .chunks import ChunkTable
from .header_bytes import MAGIC, MULTIPART, read_headers
from .layout import ExrPart

__all__ = ["write_single_part"]

_TILED = 1 << 9
_LONG_NAMES = 1 << 10
_PIECE = 1 << 20
"""Bytes copied at a time."""


def _copy(source: int, at: int, size: int, target) -> None:
    """Bytes ``at``..``at + size`` of the file ``source`` (a descriptor) appended to ``target``."""
    while size > 0:
        piece = os.pread(source, min(size, _PIECE), at)
        if not piece:
            raise EOFError
        target.write(piece)
        at, size = at + len(piece), size - len(piece)


def write_single_part(path, chosen: ExrPart, table: ChunkTable, target) -> None:
    """Write part ``chosen`` of the multi-part file ``path``, whose chunks ``table`` locates, to the binary
    file object ``target`` as a single-part OpenEXR file.

    Examples:
        >>> import pathlib, tempfile, numpy as np, OpenEXR
        >>> from torchgrade.io import exr_info
        >>> from torchgrade.io.exr.chunks import chunk_table
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "parts.exr"
        >>> planes = [{"Y": np.full((2, 3), value, np.float16)} for value in (1, 2)]
        >>> OpenEXR.File([OpenEXR.Part({"name": f"p{value}"}, p) for value, p in zip((1, 2), planes)]).write(str(path))
        >>> copy, part = path.with_name("part1.exr"), exr_info(path)[1]
        >>> with open(copy, "wb") as target:
        ...     write_single_part(path, part, chunk_table(path, part), target)
        >>> OpenEXR.File(str(copy)).parts[0].channels["Y"].pixels.tolist()
        [[2.0, 2.0, 2.0], [2.0, 2.0, 2.0]]
    """
    with open(path, "rb") as file:
        with mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            headers = read_headers(data)
            attributes = b"".join(data[a.start:a.end] for a in headers.parts[chosen.index])
        if not headers.version & MULTIPART:
            raise ValueError(f"{path}: not a multi-part file")
        tiled = chosen.kind == "tiledimage"
        version = (headers.version & 0xFF) | (headers.version & _LONG_NAMES) | (_TILED if tiled else 0)
        target.write(struct.pack("<ii", MAGIC, version) + attributes + b"\0")
        kept = table.leader - 4  # the leader without its part number
        starts = target.tell() + 8 * len(table.offsets) + np.concatenate([[0], np.cumsum(kept + table.sizes)[:-1]])
        target.write(starts.astype("<u8").tobytes())
        for offset, size in zip(table.offsets.tolist(), table.sizes.tolist()):
            _copy(file.fileno(), offset + 4, kept + size, target)
