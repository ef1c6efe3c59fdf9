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

Files are untrusted input: every size is checked against its limit and the amount of data is
checked against the file size before anything large is allocated; malformed, truncated, non-finite
or oversized files raise ``ValueError`` naming the problem.
"""

from __future__ import annotations

import os

import numpy as np
import torch

from ..lut import LUT3D, MAX_SIZE, MIN_SIZE, SHAPERS, ErrorReport, lattice, validation_colours
from ..lut.report import measure
from .atomic import atomic_write

__all__ = ["read_cube", "write_cube", "cube_text", "shaper_samples", "lattice_only", "SHAPER_SIZE", "MAX_SHAPER_SIZE"]

SHAPER_SIZE = 65536
"""Points of the 1D shaper written for LogC LUTs (Resolve's largest 1D size)."""

MAX_SHAPER_SIZE = 65536
_MAX_HEADER_LINES = 256
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
    """Read an Adobe or Resolve .cube file as a :class:`~torchgrade.LUT3D`.

    A 1D shaper section becomes a ``"curve"`` shaper, the lattice domain comes from ``DOMAIN_MIN`` /
    ``DOMAIN_MAX`` or ``LUT_3D_INPUT_RANGE``. Raises ``ValueError`` for any malformed content.
    """
    with open(path, "rb") as handle:
        header, data_offset = _read_header(handle, path)
        sizes = _check_header(header, path)
        values = _read_values(handle, os.fstat(handle.fileno()).st_size - data_offset, sizes, path)
    shaper_size, table_size = sizes
    shaper = values[: shaper_size * 3].reshape(-1, 3)
    table = values[shaper_size * 3 :].reshape(table_size, table_size, table_size, 3)
    domain = _domain(header)
    if shaper_size:
        curve_range = header.get("LUT_1D_INPUT_RANGE", [0.0, 1.0])
        return LUT3D(torch.from_numpy(table).float(), "curve", domain, curve=torch.from_numpy(shaper).float(), curve_range=curve_range)
    return LUT3D(torch.from_numpy(table).float(), "linear", domain)


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


def _read_header(handle, path):
    """Parse keyword lines up to the first data line; return ``(keywords, offset of the data)``."""
    header = {}
    for _ in range(_MAX_HEADER_LINES):
        offset = handle.tell()
        line = handle.readline(4096)
        if not line:
            break
        text = _decode(line, path).strip()
        if not text or text.startswith("#"):
            continue
        keyword, _, rest = text.partition(" ")
        if _is_number(keyword):
            handle.seek(offset)
            return header, offset
        if keyword not in _KEYWORDS:
            raise ValueError(f"{path}: unknown .cube keyword {keyword!r}")
        if keyword in header:
            raise ValueError(f"{path}: keyword {keyword} appears twice")
        header[keyword] = rest.strip() if _KEYWORDS[keyword] is None else _keyword_numbers(keyword, rest, path)
    else:
        raise ValueError(f"{path}: no LUT data after {_MAX_HEADER_LINES} header lines")
    raise ValueError(f"{path}: no LUT data in the file")


def _keyword_numbers(keyword: str, rest: str, path) -> list:
    words = rest.split()
    if len(words) != _KEYWORDS[keyword] or not all(_is_number(w) for w in words):
        raise ValueError(f"{path}: {keyword} takes {_KEYWORDS[keyword]} number(s), got {rest.strip()!r}")
    numbers = [float(w) for w in words]
    if not np.isfinite(numbers).all():
        raise ValueError(f"{path}: {keyword} must be finite, got {rest.strip()!r}")
    return numbers


def _check_header(header: dict, path):
    """Validate sizes and domains; return ``(shaper points, table points per axis)``."""
    if "LUT_3D_SIZE" not in header:
        raise ValueError(f"{path}: no LUT_3D_SIZE: not a 3D LUT (1D-only .cube files are not supported)")
    table_size = _integer(header["LUT_3D_SIZE"][0], "LUT_3D_SIZE", MIN_SIZE, MAX_SIZE, path)
    shaper_size = 0
    if "LUT_1D_SIZE" in header:
        shaper_size = _integer(header["LUT_1D_SIZE"][0], "LUT_1D_SIZE", MIN_SIZE, MAX_SHAPER_SIZE, path)
    elif "LUT_1D_INPUT_RANGE" in header:
        raise ValueError(f"{path}: LUT_1D_INPUT_RANGE without LUT_1D_SIZE")
    if ("DOMAIN_MIN" in header or "DOMAIN_MAX" in header) and "LUT_3D_INPUT_RANGE" in header:
        raise ValueError(f"{path}: both DOMAIN_MIN/MAX and LUT_3D_INPUT_RANGE given")
    low, high = _domain(header)
    if not all(h > l for l, h in zip(low, high)):
        raise ValueError(f"{path}: the 3D domain maximum must exceed its minimum, got {low} and {high}")
    curve_low, curve_high = header.get("LUT_1D_INPUT_RANGE", (0.0, 1.0))
    if not curve_high > curve_low:
        raise ValueError(f"{path}: LUT_1D_INPUT_RANGE maximum must exceed its minimum, got {curve_low} and {curve_high}")
    return shaper_size, table_size


def _domain(header: dict):
    """The 3D lattice's ``(min, max)`` RGB triples: ``LUT_3D_INPUT_RANGE``, else ``DOMAIN_MIN/MAX``, else [0, 1]."""
    if "LUT_3D_INPUT_RANGE" in header:
        low, high = header["LUT_3D_INPUT_RANGE"]
        return [low] * 3, [high] * 3
    return header.get("DOMAIN_MIN", [0.0] * 3), header.get("DOMAIN_MAX", [1.0] * 3)


def _read_values(handle, remaining_bytes: int, sizes, path) -> np.ndarray:
    """Read exactly ``(n + S³) x 3`` finite numbers, refusing files far larger than that needs."""
    shaper_size, table_size = sizes
    rows = shaper_size + table_size**3
    if remaining_bytes > rows * 3 * _MAX_BYTES_PER_VALUE + 4096:
        raise ValueError(f"{path}: {remaining_bytes} bytes of data is far more than {rows} rows of a LUT need")
    lines = [line for line in (_decode(b, path).strip() for b in handle.read().splitlines()) if line and not line.startswith("#")]
    if len(lines) != rows:
        raise ValueError(f"{path}: expected {rows} data rows ({shaper_size} shaper + {table_size}³ table), found {len(lines)}")
    words = " ".join(lines).split()
    if len(words) != rows * 3:
        raise ValueError(f"{path}: every data row must hold 3 numbers (found {len(words)} numbers in {rows} rows)")
    try:
        values = np.array(words, dtype=np.float64)
    except ValueError as error:
        raise ValueError(f"{path}: data rows must hold numbers: {error}") from None
    if not np.isfinite(values).all():
        raise ValueError(f"{path}: LUT data holds NaN or infinite values")
    return values


def _integer(value: float, keyword: str, low: int, high: int, path) -> int:
    if value != int(value) or not low <= value <= high:
        raise ValueError(f"{path}: {keyword} must be an integer from {low} to {high}, got {value:g}")
    return int(value)


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _decode(line: bytes, path) -> str:
    try:
        return line.decode("ascii")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text .cube file (non-ASCII bytes)") from None
