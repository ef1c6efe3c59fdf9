"""Conversion of an OpenEXR file's RGB, whatever its ``chromaticities`` attribute, to linear Rec.709.

The RGB -> XYZ matrix is built as OpenEXR's ``RGBtoXYZ`` builds it: from the primaries' (x, y, z)
columns scaled so that RGB (1, 1, 1) is the white with Y = 1. Unlike the usual SMPTE RP 177 form it
never divides by a primary's y, so files whose primaries lie on y = 0 (the XYZ file among OpenEXR's
samples: red (1, 0), blue (0, 0)) convert without a division by zero.
"""

from __future__ import annotations

import torch

from ...color import REC709_CHROMATICITIES, bradford_adaptation

__all__ = ["ADAPTATIONS", "XYZ_CHROMATICITIES", "is_xyz", "rgb_to_xyz", "to_rec709_matrix"]

ADAPTATIONS = ("auto", "bradford", "none")
"""How the file's white is taken to D65: a Bradford von Kries adaptation (the ACES convention for
AP0 files, and colour-science's default), none (XYZ is converted as is: what OpenEXR's sample
README means when it says its Chromaticities images look the same), or ``"auto"``: none for a file
whose primaries are CIE XYZ's own (its white is only where X = Y = Z, not a white the scene was
balanced to, so the tristimulus values are taken as they are), Bradford for every RGB space."""

XYZ_CHROMATICITIES = ((1.0, 0.0), (0.0, 1.0), (0.0, 0.0), (1 / 3, 1 / 3))
"""CIE XYZ written as RGB primaries (OpenEXR's ``XYZ.exr``): X, Y and Z, white where they are equal."""


def is_xyz(chromaticities) -> bool:
    """Whether the primaries are CIE XYZ's own (red (1, 0), green (0, 1), blue (0, 0)), whatever the white.

    Examples:
        >>> is_xyz(XYZ_CHROMATICITIES), is_xyz(((0.64, 0.33), (0.3, 0.6), (0.15, 0.06), (0.3127, 0.329)))
        (True, False)
    """
    primaries = torch.tensor(chromaticities, dtype=torch.float64)[:3]
    return bool(torch.allclose(primaries, torch.tensor(XYZ_CHROMATICITIES[:3], dtype=torch.float64), atol=1e-6))


def rgb_to_xyz(chromaticities) -> torch.Tensor:
    """float64 RGB -> XYZ matrix for ``((xr, yr), (xg, yg), (xb, yb), (xw, yw))``, white at Y = 1.

    Raises ``ValueError`` for a white with y <= 0 or primaries that span no colour space.

    Examples:
        >>> rgb_to_xyz(((1.0, 0.0), (0.0, 1.0), (0.0, 0.0), (1 / 3, 1 / 3))).round(decimals=6).tolist()  # XYZ "primaries"
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    """
    values = torch.tensor(chromaticities, dtype=torch.float64)
    if values.shape != (4, 2) or not torch.isfinite(values).all():
        raise ValueError(f"chromaticities must be four finite (x, y) pairs, got {chromaticities}")
    (x_white, y_white) = values[3].tolist()
    if y_white <= 0:
        raise ValueError(f"white point y must be above 0, got {y_white}")
    white = torch.tensor((x_white / y_white, 1.0, (1.0 - x_white - y_white) / y_white), dtype=torch.float64)
    primaries = torch.stack((values[:3, 0], values[:3, 1], 1.0 - values[:3, 0] - values[:3, 1]))
    if abs(torch.linalg.det(primaries)) < 1e-9:
        raise ValueError(f"primaries {chromaticities[:3]} are collinear: they span no colour space")
    return primaries * torch.linalg.solve(primaries, white)


def to_rec709_matrix(chromaticities, adaptation: str = "auto") -> torch.Tensor:
    """float64 matrix taking RGB with the given chromaticities to linear Rec.709 (D65), see :data:`ADAPTATIONS`.

    Examples:
        >>> aces = ((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.077), (0.32168, 0.33767))
        >>> to_rec709_matrix(aces).sum(dim=1).round(decimals=4).tolist()  # D60 white -> D65 white
        [1.0, 1.0, 1.0]
        >>> to_rec709_matrix(XYZ_CHROMATICITIES).sum(dim=1).round(decimals=4).tolist()  # E white kept: not neutral
        [1.205, 0.9483, 0.9086]
    """
    if adaptation not in ADAPTATIONS:
        raise ValueError(f"adaptation must be one of {ADAPTATIONS}, got {adaptation!r}")
    to_xyz = rgb_to_xyz(chromaticities)
    if adaptation == "bradford" or (adaptation == "auto" and not is_xyz(chromaticities)):
        to_xyz = bradford_adaptation(tuple(chromaticities[3]), REC709_CHROMATICITIES[3]) @ to_xyz
    return torch.linalg.inv(rgb_to_xyz(REC709_CHROMATICITIES)) @ to_xyz
