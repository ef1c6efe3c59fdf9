"""How far a fitted look is from its target, in what a viewer sees.

8-bit sRGB code error (the 99.9th percentile and the maximum, as the rest of torchgrade reports
LUT errors) and CIEDE2000 (Sharma, Wu and Dalal 2005), computed here in torch so the library does
not depend on colour-science at run time; the tests compare :func:`delta_e_2000` with
colour-science's ``delta_E(..., method="CIE 2000")``.

Examples:
    >>> import torch
    >>> display = torch.rand(3, 100, dtype=torch.float64)
    >>> match_errors(display, display)
    {'p99.9': 0.0, 'max': 0.0, 'delta_e_2000': 0.0}
"""

from __future__ import annotations

import math

import torch

from ..color import linear_to_srgb
from ..color.spaces import REC709_CHROMATICITIES, rgb_to_xyz_matrix
from ..lut import srgb_code_error

__all__ = ["linear_to_lab", "delta_e_2000", "match_errors", "display_codes"]

_EPSILON = 216.0 / 24389.0  # CIE's exact form of 0.008856, where L* turns from cube root to straight line
_KAPPA = 24389.0 / 27.0


def linear_to_lab(rgb: torch.Tensor) -> torch.Tensor:
    """CIE L*a*b* (D65 white) of linear Rec.709 ``(3, N)`` colours, as ``(3, N)``.

    Examples:
        >>> [round(v, 3) for v in linear_to_lab(torch.ones(3, 1, dtype=torch.float64)).flatten().tolist()]
        [100.0, 0.0, 0.0]
    """
    matrix = rgb_to_xyz_matrix(REC709_CHROMATICITIES).to(rgb)
    xyz = matrix @ rgb
    white = matrix.sum(dim=1, keepdim=True)
    ratio = xyz / white
    f = torch.where(ratio > _EPSILON, ratio.clamp_min(_EPSILON) ** (1.0 / 3.0), (_KAPPA * ratio + 16.0) / 116.0)
    return torch.stack((116.0 * f[1] - 16.0, 500.0 * (f[0] - f[1]), 200.0 * (f[1] - f[2])))


def _hue(b: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
    """Hue angle in degrees [0, 360); 0 for a neutral colour, as the formula's authors specify."""
    return torch.where((a == 0) & (b == 0), torch.zeros_like(a), torch.rad2deg(torch.atan2(b, a)) % 360.0)


def delta_e_2000(lab1: torch.Tensor, lab2: torch.Tensor) -> torch.Tensor:
    """CIEDE2000 colour difference between L*a*b* colours ``(3, N)`` (kL = kC = kH = 1), as ``(N,)``.

    Examples:
        >>> lab = torch.tensor([[50.0, 50.0], [2.6772, 0.0], [-79.7751, -82.7485]], dtype=torch.float64)
        >>> round(delta_e_2000(lab[:, :1], lab[:, 1:]).item(), 4)   # Sharma et al., test pair 1
        2.0425
    """
    (l1, a1, b1), (l2, a2, b2) = lab1, lab2
    chroma_mean = (torch.hypot(a1, b1) + torch.hypot(a2, b2)) / 2.0
    g = 0.5 * (1.0 - torch.sqrt(chroma_mean**7 / (chroma_mean**7 + 25.0**7)))
    a1, a2 = a1 * (1.0 + g), a2 * (1.0 + g)
    c1, c2 = torch.hypot(a1, b1), torch.hypot(a2, b2)
    h1, h2 = _hue(b1, a1), _hue(b2, a2)
    neutral = (c1 * c2) == 0
    dh = h2 - h1
    dh = torch.where(dh > 180.0, dh - 360.0, torch.where(dh < -180.0, dh + 360.0, dh))
    dh = torch.where(neutral, torch.zeros_like(dh), dh)
    d_hue = 2.0 * torch.sqrt(c1 * c2) * torch.sin(torch.deg2rad(dh) / 2.0)
    h_mean = torch.where((h1 - h2).abs() > 180.0, torch.where(h1 + h2 < 360.0, h1 + h2 + 360.0, h1 + h2 - 360.0), h1 + h2) / 2.0
    h_mean = torch.where(neutral, h1 + h2, h_mean)
    t = (1.0 - 0.17 * torch.cos(torch.deg2rad(h_mean - 30.0)) + 0.24 * torch.cos(torch.deg2rad(2.0 * h_mean))
         + 0.32 * torch.cos(torch.deg2rad(3.0 * h_mean + 6.0)) - 0.20 * torch.cos(torch.deg2rad(4.0 * h_mean - 63.0)))
    l_mean, c_mean = (l1 + l2) / 2.0, (c1 + c2) / 2.0
    s_l = 1.0 + 0.015 * (l_mean - 50.0) ** 2 / torch.sqrt(20.0 + (l_mean - 50.0) ** 2)
    s_c = 1.0 + 0.045 * c_mean
    s_h = 1.0 + 0.015 * c_mean * t
    r_c = 2.0 * torch.sqrt(c_mean**7 / (c_mean**7 + 25.0**7))
    r_t = -torch.sin(torch.deg2rad(60.0 * torch.exp(-(((h_mean - 275.0) / 25.0) ** 2)))) * r_c
    terms = ((l2 - l1) / s_l, (c2 - c1) / s_c, d_hue / s_h)
    return torch.sqrt(terms[0] ** 2 + terms[1] ** 2 + terms[2] ** 2 + r_t * terms[1] * terms[2])


def match_errors(reference: torch.Tensor, fitted: torch.Tensor) -> dict:
    """Errors of display-referred linear ``fitted`` against ``reference`` (both ``(3, N)``), clamped to [0, 1] as a display shows them.

    ``p99.9`` and ``max``: 8-bit sRGB code values (:func:`~torchgrade.lut.srgb_code_error`);
    ``delta_e_2000``: the mean CIEDE2000.
    """
    reference, fitted = (t.detach().double().clamp(0.0, 1.0) for t in (reference, fitted))
    delta = delta_e_2000(linear_to_lab(reference), linear_to_lab(fitted))
    errors = {"p99.9": srgb_code_error(reference, fitted, 0.999), "max": srgb_code_error(reference, fitted, 1.0),
              "delta_e_2000": float(delta.mean())}
    return {name: (0.0 if math.isclose(value, 0.0, abs_tol=1e-12) else value) for name, value in errors.items()}


def display_codes(display_linear: torch.Tensor) -> torch.Tensor:
    """sRGB-encoded display values in 8-bit code units (0..255), the space the fit's loss is measured in."""
    return 255.0 * linear_to_srgb(display_linear.clamp(0.0, 1.0))
