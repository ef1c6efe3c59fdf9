"""Reading .cube files strictly: header keywords, sizes checked against the file size, data rows streamed into float32."""

from __future__ import annotations

import io
import itertools
import os
import re
import warnings

import numpy as np
import torch

from ...base.files import open_regular
from ...lut import LUT3D, MAX_SIZE, MIN_SIZE, identity_table
from ..lines import MAX_LINE_BYTES, line_blocks
from .limits import MAX_SHAPER_SIZE

__all__ = ["read_cube", "MAX_CUBE_BYTES"]

_MAX_BYTES_PER_VALUE = 64
"""Data size limit: a file may hold at most this many bytes per expected number (plus a header)."""

MAX_CUBE_BYTES = (MAX_SHAPER_SIZE + MAX_SIZE**3) * 3 * _MAX_BYTES_PER_VALUE + MAX_LINE_BYTES
"""Largest .cube file opened: the largest shaper and table at :data:`_MAX_BYTES_PER_VALUE` a number; a regular file
only (a pipe or a device is refused unread). Its header then bounds it to what its own sizes need."""


def read_cube(path) -> LUT3D:
    """Read an Adobe or Resolve .cube file as a :class:`~torchgrade.LUT3D`, streaming the data rows.

    A 1D section before a 3D table becomes a ``"curve"`` shaper; the lattice domain comes from
    ``DOMAIN_MIN`` / ``DOMAIN_MAX`` or ``LUT_3D_INPUT_RANGE``. A 1D-only file (``LUT_1D_SIZE`` without
    ``LUT_3D_SIZE``) becomes a ``"curve"`` shaper in front of a 2³ table that is the identity on the
    curve's output range, so the LUT applies the 1D transform per channel and nothing else. Entries
    are parsed straight into float32, the table's dtype, and must be finite there (1e39 is refused).
    Any malformed content raises ``ValueError`` naming the line.

    Examples:
        >>> import tempfile, pathlib
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     path = pathlib.Path(folder) / "curve.cube"
        ...     _ = path.write_text("LUT_1D_SIZE 2\\n0 0 0\\n2 1 0.5\\n")
        ...     read_cube(path)(torch.full((1, 3, 1, 1), 0.5)).flatten().tolist()
        [1.0, 0.5, 0.25]
    """
    with open_regular(path, MAX_CUBE_BYTES, ".cube file") as handle:
        blocks = line_blocks(handle, path)
        header, first_data = _read_header(blocks, path)
        sizes = _check_header(header, path)
        _check_file_size(os.fstat(handle.fileno()).st_size, sizes, path)
        values = _read_rows(itertools.chain([first_data], blocks), sizes, path)
    shaper_size, table_size = sizes
    curve_range = header.get("LUT_1D_INPUT_RANGE", [0.0, 1.0])
    if not table_size:
        return _curve_only(torch.from_numpy(values), curve_range)
    curve = torch.from_numpy(values[:shaper_size]) if shaper_size else None
    table = torch.from_numpy(values[shaper_size:]).reshape(table_size, table_size, table_size, 3)
    if shaper_size:
        return LUT3D(table, "curve", _domain(header), curve=curve, curve_range=curve_range)
    return LUT3D(table, "linear", _domain(header))


def _curve_only(curve: torch.Tensor, curve_range) -> LUT3D:
    """A 1D transform as a LUT3D: the curve as shaper, then a 2³ table that is the identity on the curve's outputs.

    The lattice domain is the curve's range per channel, so no output is clipped and trilinear and
    tetrahedral lookups both reproduce the shaper's value. A constant channel's table is that constant
    whatever the domain, which is then [0, 1] (widening its empty range could round back to empty).
    """
    low, high = curve.min(dim=0).values, curve.max(dim=0).values
    table = identity_table(2) * (high - low) + low
    flat = high == low
    domain = (torch.where(flat, 0.0, low), torch.where(flat, 1.0, high))
    return LUT3D(table, "curve", domain, curve=curve, curve_range=curve_range)


_KEYWORDS = {
    "TITLE": None,
    "DOMAIN_MIN": 3,
    "DOMAIN_MAX": 3,
    "LUT_1D_SIZE": 1,
    "LUT_3D_SIZE": 1,
    "LUT_1D_INPUT_RANGE": 2,
    "LUT_3D_INPUT_RANGE": 2,
}
"""Keyword -> count of numbers it takes (``None``: free text)."""

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
"""A decimal number, without the extras Python's ``float`` takes (``1_0``, ``nan``, ``infinity``)."""

_CONTENT_LINE = re.compile(rb"^[ \t]*[^#\s]", re.MULTILINE)
_TRAILING_COMMENT = re.compile(rb"^[ \t]*[^#\s][^\n]*#", re.MULTILINE)
"""A ``#`` after a row's numbers: numpy's reader would drop it, OpenColorIO and colour-science refuse it."""


def _read_header(blocks, path):
    """Parse keyword lines up to the first data line; return ``(keywords, (line, block from that line on))``.

    Comment and blank lines are skipped by a regular expression, so a header padded with megabytes
    of comments costs no Python loop per line.
    """
    header = {}
    for line, block in blocks:
        start = 0
        while (found := _CONTENT_LINE.search(block, start)) is not None:
            line += block.count(b"\n", start, found.start())
            start = found.start()
            end = block.index(b"\n", start) + 1
            words = [word.decode("utf-8") for word in block[start:end].split(None, 1)]
            if _NUMBER.match(words[0]):
                return header, (line, block[start:])
            _add_keyword(header, words, line, path)
            start, line = end, line + 1
    raise ValueError(f"{path}: no LUT data in the file")


def _add_keyword(header: dict, words: list, line: int, path) -> None:
    keyword, rest = words[0], words[1].strip() if len(words) > 1 else ""
    if keyword not in _KEYWORDS:
        raise ValueError(f"{path}: line {line}: unknown .cube keyword {keyword[:80]!r}")
    if keyword in header:
        raise ValueError(f"{path}: line {line}: keyword {keyword} appears twice")
    header[keyword] = rest if _KEYWORDS[keyword] is None else _keyword_numbers(keyword, rest, line, path)


def _keyword_numbers(keyword: str, rest: str, line: int, path) -> list:
    words = rest.split()
    if len(words) != _KEYWORDS[keyword] or not all(_NUMBER.match(w) for w in words):
        raise ValueError(f"{path}: line {line}: {keyword} takes {_KEYWORDS[keyword]} number(s), got {rest[:80]!r}")
    numbers = [float(w) for w in words]
    with np.errstate(over="ignore"):
        finite = np.isfinite(np.asarray(numbers, dtype=np.float32)).all()
    if not finite:
        raise ValueError(f"{path}: line {line}: {keyword} must be finite in float32, got {rest!r}")
    return numbers


def _check_header(header: dict, path):
    """Validate sizes and ranges; return ``(shaper points, table points per axis)``, 0 for a section not present."""
    if "LUT_3D_SIZE" not in header and "LUT_1D_SIZE" not in header:
        raise ValueError(f"{path}: neither LUT_1D_SIZE nor LUT_3D_SIZE: not a .cube LUT")
    table_size = shaper_size = 0
    if "LUT_3D_SIZE" in header:
        table_size = _integer(header["LUT_3D_SIZE"][0], "LUT_3D_SIZE", MIN_SIZE, MAX_SIZE, path)
    elif "LUT_3D_INPUT_RANGE" in header or "DOMAIN_MIN" in header or "DOMAIN_MAX" in header:
        raise ValueError(f"{path}: a 3D domain without LUT_3D_SIZE")
    if "LUT_1D_SIZE" in header:
        shaper_size = _integer(header["LUT_1D_SIZE"][0], "LUT_1D_SIZE", MIN_SIZE, MAX_SHAPER_SIZE, path)
    elif "LUT_1D_INPUT_RANGE" in header:
        raise ValueError(f"{path}: LUT_1D_INPUT_RANGE without LUT_1D_SIZE")
    if ("DOMAIN_MIN" in header or "DOMAIN_MAX" in header) and "LUT_3D_INPUT_RANGE" in header:
        raise ValueError(f"{path}: both DOMAIN_MIN/MAX and LUT_3D_INPUT_RANGE given")
    _check_span("the 3D domain", *_domain(header), path)
    low, high = header.get("LUT_1D_INPUT_RANGE", (0.0, 1.0))
    _check_span("LUT_1D_INPUT_RANGE", [low], [high], path)
    return shaper_size, table_size


def _check_span(name: str, low, high, path) -> None:
    """Refuse a range whose width is not a positive normal float32: a lookup divides by it in float32."""
    with np.errstate(over="ignore"):
        width = np.float32(high) - np.float32(low)
    if not (np.isfinite(width).all() and (width >= np.finfo(np.float32).tiny).all()):
        raise ValueError(f"{path}: {name} must span a positive, finite float32 width, got {low} to {high}")


def _domain(header: dict) -> tuple[list, list]:
    """The 3D lattice's ``(min, max)`` RGB triples: ``LUT_3D_INPUT_RANGE``, else ``DOMAIN_MIN/MAX``, else [0, 1]."""
    if "LUT_3D_INPUT_RANGE" in header:
        low, high = header["LUT_3D_INPUT_RANGE"]
        return [low] * 3, [high] * 3
    return header.get("DOMAIN_MIN", [0.0] * 3), header.get("DOMAIN_MAX", [1.0] * 3)


def _check_file_size(file_bytes: int, sizes, path) -> None:
    """Refuse, before reading the data, a file far larger than its declared rows (plus a long header) need."""
    rows = sum(sizes[:1]) + sizes[1] ** 3
    if file_bytes > rows * 3 * _MAX_BYTES_PER_VALUE + MAX_LINE_BYTES:
        raise ValueError(f"{path}: {file_bytes} bytes is far more than {rows} rows of a LUT need")


def _read_rows(blocks, sizes, path) -> np.ndarray:
    """Read exactly ``n + S³`` rows of three numbers into one float32 ``(rows, 3)`` array, a block at a time."""
    shaper_size, table_size = sizes
    rows = shaper_size + table_size**3
    values = np.empty((rows, 3), dtype=np.float32)
    filled = end_line = 0
    for line, block in blocks:
        part = _block_rows(block, line, path)
        if filled + len(part) > rows:
            raise ValueError(f"{path}: line {_row_line(block, line, rows - filled)}: more than the {rows} data rows declared")
        values[filled : filled + len(part)] = part
        bad = _first_bad_row(values[: filled + len(part)], filled, shaper_size)
        if bad is not None:
            raise ValueError(f"{path}: line {_row_line(block, line, bad - filled)}: {_BAD_ROW[bad < shaper_size]}")
        filled += len(part)
        end_line = line + block.count(b"\n")
    if filled != rows:
        raise ValueError(f"{path}: the file ends at line {end_line} after {filled} of {rows} data rows "
                         f"({shaper_size} 1D + {table_size}³ 3D)")
    return values


_BAD_ROW = {
    False: "NaN, infinite or beyond float32 range",
    True: "NaN, infinite, or the 1D entries so far span more than float32 holds",
}


def _first_bad_row(values: np.ndarray, start: int, shaper_size: int):
    """The first row from ``start`` on that is not finite or, in the 1D section, widens the span past float32.

    The span bound matters because the 1D lookup interpolates ``lower + t (upper - lower)``: entries
    of -3e38 and 3e38 are finite, their difference is not, and ``0 × inf`` is NaN.
    """
    finite = np.isfinite(values[start:]).all(axis=1)
    if start < shaper_size:
        shaper = values[:shaper_size]
        with np.errstate(over="ignore", invalid="ignore"):
            span = np.maximum.accumulate(shaper) - np.minimum.accumulate(shaper)
        finite[: len(shaper) - start] &= np.isfinite(span[start:]).all(axis=1)
    return None if finite.all() else start + int(np.argmin(finite))


def _block_rows(block: bytes, line: int, path) -> np.ndarray:
    """The rows of a block of data lines as float32 ``(n, 3)``, parsed by numpy's C reader.

    numpy rejects ``1_0`` (which Python's ``float`` takes), and a row of two or four numbers; the
    line is then found by a slower scan that is only run on failure.
    """
    if block.isspace() or block.count(b"\n#") + block.startswith(b"#") == block.count(b"\n"):
        return np.empty((0, 3), dtype=np.float32)  # only blank or only comment lines, counted at memchr speed
    if b"#" in block and _TRAILING_COMMENT.search(block):
        raise ValueError(_bad_row_message(block, line, path))
    try:
        with warnings.catch_warnings():
            # Blocks of only comments hold no rows; 1e39 overflows float32 to inf, refused later with its line.
            warnings.simplefilter("ignore")
            part = np.loadtxt(io.BytesIO(block), dtype=np.float32, ndmin=2, comments="#")
    except ValueError:
        part = None
    if part is not None and part.size == 0:
        return np.empty((0, 3), dtype=np.float32)
    if part is None or part.shape[1] != 3:
        raise ValueError(_bad_row_message(block, line, path))
    return part


def _data_words(block: bytes, line: int):
    """``(line number, words)`` of each data line of a block (not blank, not a comment)."""
    for number, text in enumerate(block.decode("utf-8").split("\n"), line):
        words = text.split()
        if words and not words[0].startswith("#"):
            yield number, words


def _row_line(block: bytes, line: int, row: int) -> int:
    """The line number of data row ``row`` (counted from 0) of a block."""
    return next(itertools.islice(_data_words(block, line), row, None))[0]


def _bad_row_message(block: bytes, line: int, path) -> str:
    for number, words in _data_words(block, line):
        if len(words) != 3 or not all(_NUMBER.match(w) for w in words):
            return f"{path}: line {number}: a data row must be 3 numbers, got {' '.join(words)[:80]!r}"
    return f"{path}: lines from {line}: unreadable LUT data"


def _integer(value: float, keyword: str, low: int, high: int, path) -> int:
    if value != int(value) or not low <= value <= high:
        raise ValueError(f"{path}: {keyword} must be an integer from {low} to {high}, got {value:g}")
    return int(value)
