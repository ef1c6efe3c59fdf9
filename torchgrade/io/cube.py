""".cube LUT files (Adobe/IRIDAS and DaVinci Resolve conventions), read strictly and written atomically.

A file is a header of keywords then data lines of three numbers, red varying fastest::

    TITLE "name"                        # optional
    DOMAIN_MIN r g b / DOMAIN_MAX r g b  # Adobe: the 3D lattice's input range per channel
    LUT_1D_SIZE n                       # Resolve: a 1D shaper applied before the 3D table ...
    LUT_1D_INPUT_RANGE lo hi            # ... sampled at n points evenly over [lo, hi]
    LUT_3D_SIZE S
    LUT_3D_INPUT_RANGE lo hi            # Resolve: the 3D lattice's input range
    <n shaper lines> <S³ table lines>

Linear-shaper LUTs are written in the Adobe form. Any other shaper (LogC) is written in the Resolve
form, as Resolve and OpenColorIO's baker do: the 1D section maps linear input to normalised lattice
coordinates, so every tool that reads Resolve .cube files applies the shaper itself. The 1D section
samples the shaper at evenly spaced linear values; between samples the shaper is linear, the one
approximation of the interchange (see :data:`SHAPER_SIZE`).

The format has no output clamp: a display-referred LUT (``output_range=(0, 1)``, baked without the
tone mapper's final clip) is written as its table, whose entries may leave [0, 1] slightly, and the
file read back has no ``output_range``. After a reader's lookup the display's own clip to [0, 1]
gives the same result as the original LUT.

A 1D-only file (``LUT_1D_SIZE`` and no ``LUT_3D_SIZE``, as Resolve writes per-channel curves) is
read as a ``"curve"`` shaper before a 2³ identity table on the curve's range (see :func:`read_cube`).

Files are untrusted input: every size is checked against its limit and the amount of data is
checked against the file size before anything large is allocated; the data are then read in blocks
(:mod:`torchgrade.io.lines`) straight into the one float32 table, so a read holds little more than
the table. Malformed, truncated, non-finite (in float32) or oversized files raise ``ValueError``
naming the problem and its line.
"""

from __future__ import annotations

import io
import itertools
import os
import re
import warnings

import numpy as np
import torch

from ..lut import LUT3D, MAX_SIZE, MIN_SIZE, SHAPERS, ErrorReport, identity_table, lattice, validation_colours
from ..lut.report import measure
from .atomic import atomic_write
from .lines import MAX_LINE_BYTES, line_blocks

__all__ = ["read_cube", "write_cube", "cube_text", "shaper_samples", "lattice_only", "SHAPER_SIZE", "MAX_SHAPER_SIZE"]

SHAPER_SIZE = 65536
"""Points of the 1D shaper written for LogC LUTs (Resolve's largest 1D size)."""

MAX_SHAPER_SIZE = 65536
_MAX_BYTES_PER_VALUE = 64
"""Data size limit: a file may hold at most this many bytes per expected number (plus a header)."""


# ---------------------------------------------------------------- writing


def write_cube(path, lut: LUT3D, title: str = "torchgrade", shaper_size: int = SHAPER_SIZE, shaper_section: bool = True,
               top: float = 1.0):
    """Write ``lut`` to ``path`` as a .cube file (atomically: a failed write leaves nothing behind).

    ``shaper_section=False`` writes a 3D-only file (Adobe form, no 1D section: what ffmpeg's
    ``lut3d`` and other 3D-only readers accept): a LUT with a shaper is resampled onto a linear
    lattice over ``[0, top]`` (:func:`lattice_only`), and the :class:`~torchgrade.lut.ErrorReport` of
    that resampling against ``lut`` is returned. Otherwise returns ``None``.
    """
    cost = None
    if not shaper_section and not SHAPERS[lut.shaper].cube_domain_form:
        lut, cost = lattice_only(lut, top)
    text = cube_text(lut, title, shaper_size)
    atomic_write(path, lambda temporary: _write_text(temporary, text))
    return cost


def lattice_only(lut: LUT3D, top: float = 1.0) -> tuple:
    """``(linear-shaper LUT over [0, top], ErrorReport)``: ``lut`` sampled on an evenly spaced linear lattice of its size.

    The report measures the resampled LUT against ``lut`` on the validation colours (HDR ones when
    ``top`` exceeds 1): shadows lose the shaper's resolution and inputs above ``top`` clamp.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> resampled, cost = lattice_only(LUT3D(identity_table(3), "logc"))
        >>> resampled.shaper, cost.colours > 0
        ('linear', True)
    """
    if not top > 0:
        raise ValueError(f"3D-only lattice top must be above 0, got {top}")
    points = (lattice(lut.size) * top).reshape(1, -1, 3).permute(0, 2, 1).unsqueeze(-1)  # (1, 3, S³, 1)
    with torch.no_grad():
        table = lut(points.float()).double().squeeze(-1)[0].t().reshape(lut.size, lut.size, lut.size, 3)
    resampled = LUT3D(table.float(), "linear", domain=(0.0, top), output_range=lut.output_range)
    colours = validation_colours(hdr=top > 1.0).reshape(1, 3, 1, -1)
    with torch.no_grad():
        cost = measure(resampled, (colours, lut(colours.float()).double()), 1.0)
    return resampled, cost


def cube_text(lut: LUT3D, title: str = "torchgrade", shaper_size: int = SHAPER_SIZE) -> str:
    """The .cube file contents of ``lut``: Adobe form for a shaper without a 1D section, Resolve form otherwise.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> cube_text(LUT3D(identity_table(2))).splitlines()[:4]
        ['TITLE "torchgrade"', 'DOMAIN_MIN 0.0 0.0 0.0', 'DOMAIN_MAX 1.0 1.0 1.0', 'LUT_3D_SIZE 2']
    """
    if '"' in title or "\n" in title:
        raise ValueError(f"cube title must not contain quotes or newlines, got {title!r}")
    section = shaper_samples(lut, shaper_size)
    if section is None:
        lines = [f'TITLE "{title}"']
        lines += [f"DOMAIN_MIN {_numbers(lut.domain_min)}", f"DOMAIN_MAX {_numbers(lut.domain_max)}"]
        lines += [f"LUT_3D_SIZE {lut.size}"]
    else:
        low, high, shaper = section
        lines = [f"# {title}"]  # OpenColorIO's Resolve reader rejects the TITLE keyword
        lines += [f"LUT_1D_SIZE {shaper_size}", f"LUT_1D_INPUT_RANGE {low!r} {high!r}"]
        lines += [f"LUT_3D_SIZE {lut.size}", "LUT_3D_INPUT_RANGE 0.0 1.0"]
        lines += _data_lines(shaper)
    lines += _data_lines(lut.linear_table().detach().reshape(-1, 3))
    return "\n".join(lines) + "\n"


def shaper_samples(lut: LUT3D, count: int):
    """The Resolve 1D section of ``lut``'s shaper, ``(low, high, (count, 3) lattice coordinates)``, or ``None``.

    The shaper object gives it (:meth:`~torchgrade.lut.Shaper.cube_section`); a shaper whose
    ``cube_domain_form`` is true (linear) has none: the Adobe ``DOMAIN_MIN/MAX`` keywords state it.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> low, high, samples = shaper_samples(LUT3D(identity_table(2), "logc"), 16)
        >>> samples.shape
        torch.Size([16, 3])
    """
    shaper = SHAPERS[lut.shaper]
    if shaper.cube_domain_form:
        return None
    if not MIN_SIZE <= count <= MAX_SHAPER_SIZE:
        raise ValueError(f"shaper size must be from {MIN_SIZE} to {MAX_SHAPER_SIZE}, got {count}")
    with torch.no_grad():
        return shaper.cube_section(lut, count)


def _numbers(values: torch.Tensor) -> str:
    return " ".join(repr(float(v)) for v in values)


def _data_lines(rows: torch.Tensor) -> list:
    """Rows rounded to float32 and printed with ``%.9g``: enough digits to read back bit-exact."""
    array = rows.detach().cpu().float().double().numpy()
    return [f"{r:.9g} {g:.9g} {b:.9g}" for r, g, b in array]


def _write_text(path: str, text: str) -> None:
    with open(path, "w", encoding="ascii") as handle:
        handle.write(text)


# ---------------------------------------------------------------- reading


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
    with open(path, "rb") as handle:
        blocks = line_blocks(handle, path)
        header, first_data = _read_header(blocks, path)
        sizes = _check_header(header, path)
        _check_file_size(os.fstat(handle.fileno()).st_size, sizes, path)
        values = _read_rows(itertools.chain([first_data], blocks), sizes, path)
    shaper_size, table_size = sizes
    curve = torch.from_numpy(values[:shaper_size]) if shaper_size else None
    curve_range = header.get("LUT_1D_INPUT_RANGE", [0.0, 1.0])
    if not table_size:
        return _curve_only(curve, curve_range)
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
            words = [word.decode("ascii") for word in block[start:end].split(None, 1)]
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
        finite = np.isfinite(np.float32(numbers)).all()
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
    _check_span("LUT_1D_INPUT_RANGE", *([value] for value in header.get("LUT_1D_INPUT_RANGE", (0.0, 1.0))), path)
    return shaper_size, table_size


def _check_span(name: str, low, high, path) -> None:
    """Refuse a range whose width is not a positive normal float32: a lookup divides by it in float32."""
    with np.errstate(over="ignore"):
        width = np.float32(high) - np.float32(low)
    if not (np.isfinite(width).all() and (width >= np.finfo(np.float32).tiny).all()):
        raise ValueError(f"{path}: {name} must span a positive, finite float32 width, got {low} to {high}")


def _domain(header: dict):
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
    for number, text in enumerate(block.decode("ascii").split("\n"), line):
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
