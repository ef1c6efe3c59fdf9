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

from .limits import MAX_SHAPER_SIZE, SHAPER_SIZE
from .read import read_cube
from .write import cube_text, lattice_only, shaper_samples, write_cube

__all__ = ["read_cube", "write_cube", "cube_text", "shaper_samples", "lattice_only", "SHAPER_SIZE", "MAX_SHAPER_SIZE"]
