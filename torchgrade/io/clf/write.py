"""Academy/ASC Common LUT Format (CLF 3.0, SMPTE ST 2136-1) files of a :class:`~torchgrade.LUT3D`, written atomically.

Unlike ``.cube``, CLF states a shaper exactly: a LogC shaper is a ``Log`` node (``linToLog``,
``c log10(a x + b) + d``, Unity's constants), the lattice domain a ``Range`` node (which clamps, as
the lookup does), a fitted shaper's curve a ``LUT1D`` after a ``Range`` onto its LogC span, the
tail of ``"logc_extended"`` and ``"logc_hdr"`` the same way (piecewise linear in LogC codes, its knots on the table's points, so
linear interpolation in the ``LUT1D`` is exact), and a
display-referred LUT's clamp a final ``Range`` to [0, 1]. The 3D table is written with linear
entries in CLF's order (blue fastest) and the interpolation the LUT is meant for.

Examples:
    >>> from torchgrade.lut import LUT3D, identity_table
    >>> [line.strip().split()[0] for line in clf_text(LUT3D(identity_table(2), "logc")).splitlines()[3:6]]
    ['<Log', '<LogParams', '</Log>']
"""

from __future__ import annotations

import math
from typing import Optional
from xml.sax.saxutils import escape, quoteattr

import torch

from ...color.transfer import LOGC_A, LOGC_B, LOGC_C, LOGC_D
from ...lut import LUT3D, SHAPERS
from ...lut.shapers import LogCHDRShaper
from ..atomic import atomic_write
from ..cube.write import check_title

__all__ = ["write_clf", "clf_text"]

_DEPTHS = 'inBitDepth="32f" outBitDepth="32f"'


def write_clf(path, lut: LUT3D, title: str = "torchgrade", interpolation: Optional[str] = None) -> None:
    """Write ``lut`` to ``path`` as a CLF file (atomically: a failed write leaves nothing behind), to be interpolated
    with ``interpolation`` (the LUT's own by default)."""
    text = clf_text(lut, title, interpolation)

    def write(temporary: str) -> None:
        with open(temporary, "w", encoding="utf-8") as handle:
            handle.write(text)

    atomic_write(path, write)


def clf_text(lut: LUT3D, title: str = "torchgrade", interpolation: Optional[str] = None) -> str:
    """The CLF document of ``lut``: shaper nodes, the lattice ``Range``, the ``LUT3D``, and the display clamp.

    Examples:
        >>> from torchgrade.lut import LUT3D, identity_table
        >>> '<LUT3D inBitDepth="32f" outBitDepth="32f" interpolation="trilinear">' in clf_text(LUT3D(identity_table(2)), interpolation="trilinear")
        True
    """
    interpolation = interpolation or lut.interpolation
    if interpolation not in ("trilinear", "tetrahedral"):
        raise ValueError(f"CLF interpolation must be 'trilinear' or 'tetrahedral', got {interpolation!r}")
    check_title(title, "CLF")  # XML 1.0 has no form for control characters: the file would not parse
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', f'<ProcessList compCLFversion="3" id={quoteattr(title)}>',
             f"  <Description>{escape(title)}: {lut.size}³ {lut.shaper} LUT</Description>"]
    lines += _shaper_nodes(lut)
    lines += _range(lut.domain_min, lut.domain_max, 0.0, 1.0)
    table = lut.linear_table().detach().double().permute(2, 1, 0, 3).reshape(-1, 3)  # [r, g, b]: blue fastest
    lines += [f'  <LUT3D {_DEPTHS} interpolation="{interpolation}">', f'    <Array dim="{lut.size} {lut.size} {lut.size} 3">']
    lines += _rows(table)
    lines += ["    </Array>", "  </LUT3D>"]
    if lut.output_range is not None:
        low, high = lut.output_range
        lines += _range(torch.tensor(low), torch.tensor(high), low, high)
    lines.append("</ProcessList>")
    return "\n".join(lines) + "\n"


def _shaper_nodes(lut: LUT3D) -> list:
    """The nodes from linear input to the shaper's code values (none for the linear shaper)."""
    if lut.shaper == "linear":
        return []
    lines = []
    shaper = SHAPERS[lut.shaper]
    tail = isinstance(shaper, LogCHDRShaper)
    if lut.shaper in ("logc", "fitted") or tail:
        lines += [f'  <Log {_DEPTHS} style="linToLog">',
                  f'    <LogParams base="10" linSideSlope="{LOGC_A!r}" linSideOffset="{LOGC_B!r}" '
                  f'logSideSlope="{LOGC_C!r}" logSideOffset="{LOGC_D!r}"/>', "  </Log>"]
    curve, curve_range = lut.curve, lut.curve_range
    if isinstance(shaper, LogCHDRShaper):  # the tail after LogC: piecewise linear with its knots on table points, so exact
        bottom = min(0.0, math.floor(float(lut.domain_min.min()) * 10.0) / 10.0)
        curve_range, curve = shaper.logc_table(bottom)
    if curve is not None:  # a fitted curve over LogC codes, the tail, or a .cube 1D section over linear values
        low, high = curve_range
        lines += _range(torch.tensor(low, dtype=torch.float64), torch.tensor(high, dtype=torch.float64), 0.0, 1.0)
        lines += [f'  <LUT1D {_DEPTHS}>', f'    <Array dim="{curve.shape[0]} 3">']
        lines += _rows(curve.detach().double())
        lines += ["    </Array>", "  </LUT1D>"]
    return lines


def _range(low: torch.Tensor, high: torch.Tensor, out_low: float, out_high: float) -> list:
    """A clamping ``Range`` node from ``[low, high]`` onto ``[out_low, out_high]``; per-channel bounds need a ``Matrix`` first."""
    low, high = low.double().reshape(-1).expand(3), high.double().reshape(-1).expand(3)
    lines = []
    if not (bool((low == low[0]).all()) and bool((high == high[0]).all())):
        scale = (high[0] - low[0]) / (high - low)
        offset = low[0] - low * scale
        rows = [" ".join(repr(float(scale[c])) if k == c else ("0" if k < 3 else repr(float(offset[c]))) for k in range(4)) for c in range(3)]
        lines += [f'  <Matrix {_DEPTHS}>', '    <Array dim="3 4 3">', *(f"      {row}" for row in rows), "    </Array>", "  </Matrix>"]
    lines += [f'  <Range {_DEPTHS}>', f"    <minInValue>{float(low[0])!r}</minInValue>", f"    <maxInValue>{float(high[0])!r}</maxInValue>",
              f"    <minOutValue>{out_low!r}</minOutValue>", f"    <maxOutValue>{out_high!r}</maxOutValue>", "  </Range>"]
    return lines


def _rows(values: torch.Tensor) -> list:
    """Rows of three numbers, float32-exact (``%.9g``)."""
    return [f"      {r:.9g} {g:.9g} {b:.9g}" for r, g, b in values.float().double().tolist()]
