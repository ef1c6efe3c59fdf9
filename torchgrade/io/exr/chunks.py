"""A part's chunk offset table, checked from the file's bytes before the bindings decode a pixel.

OpenEXR's core library does not refuse a damaged file: where a header lacks an attribute the format
requires it stands in a default (a 64x64 data window), and a damaged offset table it rebuilds from
the chunks it finds (``reconstruct_chunk_table`` in OpenEXRCore's ``chunk.c``), printing its
complaints to standard error; the part then decodes partly filled, or from the wrong chunks. So the
bindings are only given a part of a file whose headers hold every required attribute
(:func:`torchgrade.io.exr.header_bytes.check_required`) and whose table follows the file layout
document (https://openexr.com/en/latest/OpenEXRFileLayout.html) as the core reads it:

- the parts' tables follow the headers, one 8-byte offset a chunk: a scanline part has
  ceil(height / lines per chunk) chunks (the lines by compression), a tiled part the tiles of each
  of its levels (one level, or mip-map or rip-map levels rounded down or up), at most 2^20 (the
  core's own bound); a ``chunkCount`` attribute (every part of a multi-part file has one) says the same;
- each offset points past the tables at a chunk whose leader (the part number in a multi-part file;
  the y of a block of scanlines, or a tile's x, y, level x and level y; the data size) names this
  part and this slot of the table, and whose data, not empty, ends inside the file. The slots go
  level by level (for rip-maps level y outer, level x inner), then rows of tiles, then tiles, as
  the core computes a tile's slot (``validate_and_compute_tile_chunk_off``);
- the data is no larger than the chunk's samples uncompressed (a whole block of scanlines, a tile
  cut at its level's edge), and exactly that size uncompressed (the core's checks on a leader);
- no two chunks overlap, and a scanline part's chunks lie in increasing offsets when its
  ``lineOrder`` is INCREASING_Y, decreasing when DECREASING_Y (RANDOM_Y: any order).

What a chunk's data decompresses to is left to the library, which raises when it cannot (see
:mod:`torchgrade.io.exr.decode`).
"""

from __future__ import annotations

import functools
import mmap
import struct
from dataclasses import dataclass

import numpy as np

from .header_bytes import MULTIPART, Headers, channel_list, check_required, read_headers, value
from .layout import ExrPart

__all__ = ["MAX_CHUNKS", "library_compressions", "ChunkTable", "chunk_table"]

MAX_CHUNKS = 1 << 20
"""Most chunks a part may have: OpenEXRCore refuses larger offset tables (``extract_chunk_table``)."""

_LINES_PER_CHUNK = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256, 10: 256, 11: 32, 12: 256, 13: 1}
"""Scanlines a chunk holds, by compression code: NO, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A, DWAA, DWAB, HTJ2K256,
HTJ2K32 (file layout document, "Regular Scan Line Blocks"), LJ2K (HTJ2K256's blocks, OpenEXR's ``internal_ht_common``)
and ZSTD (one line, as OpenEXR 3.5.3 writes it: 1000 chunks for 1000 lines). A code not here that the library knows
is a newer library's: its scanline parts are left to the library (:func:`chunk_table`)."""


@functools.cache
def library_compressions() -> frozenset[int]:
    """The compression codes the installed OpenEXR knows. It reads any other code as ZIP without a word (3.5.3), so a
    file holding one is refused here.

    Examples:
        >>> {0, 3} <= library_compressions()  # NO_COMPRESSION, ZIP_COMPRESSION
        True
    """
    import OpenEXR  # the bindings load at the first read, not with torchgrade.io

    codes = OpenEXR.Compression
    return frozenset(int(code) for code in codes.__members__.values() if code != codes.NUM_COMPRESSION_METHODS)


_LINE_ORDERS = ("INCREASING_Y", "DECREASING_Y", "RANDOM_Y")

_DAMAGE = (ValueError, IndexError, KeyError, struct.error)
"""What reading damaged header bytes raises (KeyError: an attribute ``exr_info`` saw, gone since)."""

_BLOCK = 1 << 16
"""Chunk leaders gathered at a time (their index array: 12 MiB at most)."""


@dataclass(frozen=True)
class ChunkTable:
    """Where each chunk of a part lies, in table order: its leader of ``leader`` bytes at ``offsets[i]``,
    then ``sizes[i]`` bytes of data."""

    offsets: np.ndarray
    sizes: np.ndarray
    leader: int


def _level_sides(size: int, levels: int, round_up: bool) -> list[int]:
    """Each level's side, of a side of ``size`` pixels (OpenEXRCore's ``calc_level_size``)."""
    return [max(1, -(-size >> level) if round_up else size >> level) for level in range(levels)]


def _tiles(width: int, height: int, tiles: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``(tile x, tile y, level x, level y)`` of each slot of a tiled part's table, and the pixels of
    each tile (cut at its level's edge), or ``ValueError``."""
    tile_width, tile_height, mode = tiles
    levels, round_up = mode & 0xF, mode >> 4 == 1
    log2 = (lambda n: (n - 1).bit_length()) if round_up else (lambda n: n.bit_length() - 1)  # noqa: E731
    if tile_width < 1 or tile_height < 1 or levels > 2 or mode >> 4 > 1:
        raise ValueError(f"its tiles (tileDesc) {tile_width}x{tile_height} with mode {mode:#x} describe no tiling")
    x_levels, y_levels = {0: (1, 1), 1: (log2(max(width, height)) + 1,) * 2, 2: (log2(width) + 1, log2(height) + 1)}[levels]
    widths, heights = _level_sides(width, x_levels, round_up), _level_sides(height, y_levels, round_up)
    pairs = [(x, y) for y in range(y_levels) for x in range(x_levels)] if levels == 2 else [(x, x) for x in range(x_levels)]
    count = sum(-(-widths[x] // tile_width) * -(-heights[y] // tile_height) for x, y in pairs)
    if count > MAX_CHUNKS:
        raise ValueError(f"its tiles (tileDesc) {tile_width}x{tile_height} make {count} chunks, more than the {MAX_CHUNKS} "
                         "OpenEXR reads")
    slots, pixels = [], []
    for x, y in pairs:
        across = -(-widths[x] // tile_width)
        rows, columns = np.divmod(np.arange(across * -(-heights[y] // tile_height)), across)
        slots.append(np.stack([columns, rows, np.full_like(rows, x), np.full_like(rows, y)], axis=1))
        pixels.append(np.minimum(tile_width, widths[x] - columns * tile_width) * np.minimum(tile_height, heights[y] - rows * tile_height))
    return np.concatenate(slots), np.concatenate(pixels)


def _layout(attributes: dict, data, part: ExrPart) -> tuple[np.ndarray, np.ndarray]:
    """The coordinates each slot of the part's table names (``(y,)`` of a block of scanlines, or a tile's
    ``(x, y, level x, level y)``), and the pixels whose samples bound each chunk's data size."""
    x_min, y_min, x_max, y_max = value(data, attributes["dataWindow"])
    width, height = x_max - x_min + 1, y_max - y_min + 1
    if part.kind == "tiledimage":
        return _tiles(width, height, value(data, attributes["tiles"]))
    (compression,) = value(data, attributes["compression"])
    lines = _LINES_PER_CHUNK[compression]
    count = -(-height // lines)
    if count > MAX_CHUNKS:
        raise ValueError(f"its {height} lines in blocks of {lines} make {count} chunks, more than the {MAX_CHUNKS} OpenEXR reads")
    # a block's bound is a whole block's pixels, even the last (OpenEXRCore's ``unpacked_size_per_chunk``)
    return (y_min + lines * np.arange(count))[:, None], np.full(count, lines * width)


def _chunk_counts(headers: Headers, data, part: ExrPart, count: int) -> list[int]:
    """Each part's chunk count as its ``chunkCount`` says (every part of a multi-part file has one), else
    ``count``, the one the part's header gives; ``ValueError`` where they differ."""
    counts = []
    for index in range(len(headers.parts)):
        found = headers.attributes(index).get("chunkCount")
        counts.append(value(data, found)[0] if found is not None and found.kind == "int" else count)
    if min(counts) < 0:
        raise ValueError(f"a part has a chunkCount of {min(counts)}")
    if counts[part.index] != count:
        raise ValueError(f"its chunkCount of {counts[part.index]} is not the chunk count of {count} its header gives")
    return counts


def _first(mask: np.ndarray) -> int | None:
    found = np.flatnonzero(mask)
    return int(found[0]) if len(found) else None


def _leaders(data, offsets: np.ndarray, leader: int) -> np.ndarray:
    """The ``leader // 4`` little-endian ints at each offset."""
    raw = np.frombuffer(data, np.uint8)
    try:
        fields = np.empty((len(offsets), leader // 4), np.int32)
        for start in range(0, len(offsets), _BLOCK):
            where = offsets[start:start + _BLOCK, None] + np.arange(leader)
            fields[start:start + _BLOCK] = raw[where].view("<i4")
        return fields
    finally:
        del raw  # a live view of the map would keep it from closing


def _left_to_library(attributes: dict, data, part: ExrPart) -> bool:
    """True for a scanline part whose compression the library knows and these checks do not (how many lines its
    chunks hold): a newer library's. ``ValueError`` for a code the library does not know either."""
    (compression,) = value(data, attributes["compression"])
    if compression not in library_compressions():
        raise ValueError(f"its compression {compression} is none the installed OpenEXR knows")
    return part.kind != "tiledimage" and compression not in _LINES_PER_CHUNK


def _check(headers: Headers, data, part: ExrPart) -> ChunkTable:
    attributes = headers.attributes(part.index)
    slots, pixels = _layout(attributes, data, part)
    counts = _chunk_counts(headers, data, part, len(slots))
    multipart = bool(headers.version & MULTIPART)
    table, first = headers.end + 8 * sum(counts[:part.index]), headers.end + 8 * sum(counts)
    leader = 4 * (int(multipart) + slots.shape[1] + 1)
    if first + leader * len(slots) > len(data):
        raise ValueError(f"its {len(slots)} chunks cannot fit in the file of {len(data)} bytes with the offset tables")
    offsets = np.frombuffer(data[table:table + 8 * len(slots)], "<u8")
    outside = _first((offsets < first) | (offsets > len(data) - leader))
    if outside is not None:
        raise ValueError(f"chunk {outside} at offset {offsets[outside]}, outside the chunks of a file of {len(data)} bytes")
    offsets = offsets.astype(np.int64)
    fields = _leaders(data, offsets, leader)
    if multipart and (stranger := _first(fields[:, 0] != part.index)) is not None:
        raise ValueError(f"chunk {stranger} at offset {offsets[stranger]} belongs to part {fields[stranger, 0]}")
    coordinates, sizes = fields[:, int(multipart):-1], fields[:, -1].astype(np.int64)
    if (misplaced := _first((coordinates != slots).any(axis=1))) is not None:
        names = "tile x, y, level x, y" if slots.shape[1] == 4 else "y"
        raise ValueError(f"chunk {misplaced} at offset {offsets[misplaced]} holds {names} {coordinates[misplaced].tolist()}, "
                         f"not its slot's {slots[misplaced].tolist()}")
    ends = offsets + leader + sizes
    if (broken := _first((sizes <= 0) | (ends > len(data)))) is not None:
        raise ValueError(f"chunk {broken} of {sizes[broken]} bytes at offset {offsets[broken]} is empty or runs past the end "
                         f"of the file of {len(data)} bytes")
    # OpenEXR stores a chunk uncompressed when compressing does not make it smaller, and refuses more
    # (subsampled channels take less than this bound: it is exact only without them)
    unpacked = pixels * sum(channel_list(data, attributes["channels"]).values())
    exact = value(data, attributes["compression"]) == (0,) and all(sampling == (1, 1) for sampling in part.channels.values())
    if (swollen := _first(sizes != unpacked if exact else sizes > unpacked)) is not None:
        raise ValueError(f"chunk {swollen} holds {sizes[swollen]} bytes of data for pixels of {unpacked[swollen]} bytes "
                         f"uncompressed")
    order = np.argsort(offsets, kind="stable")
    if (overlap := _first(ends[order[:-1]] > offsets[order[1:]])) is not None:
        raise ValueError(f"chunks {order[overlap]} and {order[overlap + 1]} overlap (at offsets {offsets[order[overlap]]} and "
                         f"{offsets[order[overlap + 1]]})")
    (line_order,) = value(data, attributes["lineOrder"])
    if line_order >= len(_LINE_ORDERS):
        raise ValueError(f"its lineOrder {line_order} is none OpenEXR knows")
    steps = np.diff(offsets) * (1 if line_order == 0 else -1)
    if part.kind != "tiledimage" and line_order < 2 and (back := _first(steps < 0)) is not None:
        raise ValueError(f"chunk {back + 1} at offset {offsets[back + 1]} is out of its {_LINE_ORDERS[line_order]} line "
                         f"order (chunk {back} is at {offsets[back]})")
    return ChunkTable(offsets, sizes, leader)


def chunk_table(path, part: ExrPart) -> ChunkTable | None:
    """Where part ``part`` of the file at ``path`` keeps its chunks, once the headers and the part's
    table are checked against the rules above; ``ValueError`` naming the file and the first attribute,
    or the part and the first chunk, that breaks one.

    ``None`` for a scanline part whose compression the installed library knows and this module does not (how many
    lines its chunks hold): a newer library's, which the library then decodes or refuses itself.

    Examples:
        >>> import pathlib, struct, tempfile, torch, torchgrade as tg
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 40, 8))  # ZIP: blocks of 16 lines
        >>> part, = tg.io.exr_info(path)
        >>> table = chunk_table(path, part)
        >>> len(table.offsets), table.leader
        (3, 8)
        >>> data = bytearray(path.read_bytes())
        >>> struct.pack_into("<i", data, table.offsets[1], 0)  # block 1 says it starts at line 0
        >>> _ = path.write_bytes(bytes(data))
        >>> chunk_table(path, part)
        Traceback (most recent call last):
        ValueError: ...rgb.exr: damaged OpenEXR file (part 0: chunk 1 at offset ... holds y [0], not its slot's [16])
    """
    try:
        with open(path, "rb") as file, mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            headers = read_headers(data)
            check_required(headers, data)  # its messages name the part
            try:
                if _left_to_library(headers.attributes(part.index), data, part):
                    return None
                return _check(headers, data, part)
            except _DAMAGE as error:
                raise ValueError(f"part {part.index}: {error}") from None
    except _DAMAGE as error:
        raise ValueError(f"{path}: damaged OpenEXR file ({error})") from None
