"""AgX (Troy Sobotka): Benjamin Wrensch's minimal form and Godot 4.4's approximation of Blender 4's."""

from __future__ import annotations

import math

import torch

from ..color import safe_pow
from .base import apply_rows, display, limited

__all__ = ["agx", "agx_godot"]

_AGX_MIN_EV = math.log2(0.18) - 10.0
_AGX_MAX_EV = math.log2(0.18) + 6.5
"""AgX's log2 range: 10 stops below and 6.5 above middle grey 0.18 (−12.47393 .. 4.026069)."""
_AGX_INSET = (
    (0.842479062253094, 0.0784335999999992, 0.0792237451477643),
    (0.0423282422610123, 0.878468636469772, 0.0791661274605434),
    (0.0423756549057051, 0.0784336, 0.879142973793104),
)
_AGX_OUTSET = (
    (1.19687900512017, -0.0980208811401368, -0.0990297440797205),
    (-0.0528968517574562, 1.15190312990417, -0.0989611768448433),
    (-0.0529716355144438, -0.0980434501171241, 1.15107367264116),
)
_AGX_SIGMOID = (-0.00232, 0.1191, 0.4298, -6.868, 31.96, -40.14, 15.5)
"""Wrensch's 6th-order fit of AgX's default-contrast sigmoid, ascending powers (mean error² 3.67e-6)."""
_AGX_GODOT_INSET = (
    (0.54490813676363087053, 0.37377945959812267119, 0.081384976686647875101),
    (0.14044005884001287035, 0.75410959864013760045, 0.10543358536857773485),
    (0.088827411851915368603, 0.17887712465043811023, 0.73224999956948382528),
)
"""Godot 4.4: linear sRGB → Rec.2020, then Blender's AgX inset."""
_AGX_GODOT_OUTSET = (
    (1.9645509602733325934, -0.85585845117807513559, -0.10886710826831608324),
    (-0.29932243390911083839, 1.3264510741502356555, -0.027084020983874825605),
    (-0.16436833806080403409, -0.23822464068860595117, 1.402665347143271889),
)
"""Godot 4.4: Blender's AgX outset, then Rec.2020 → linear sRGB."""
_AGX_GODOT_SIGMOID = (0.0, 0.021, 4.0111, -25.682, 70.359, -74.778, 27.069)
"""Godot 4.4's 6th-order fit of Blender's AgX sigmoid (EaryChow's), ascending powers, zero at 0."""


def _polynomial(x: torch.Tensor, coefficients) -> torch.Tensor:
    """``Σ cₖ xᵏ`` by Horner's rule, ``coefficients`` in ascending powers."""
    result = torch.full_like(x, coefficients[-1])
    for c in reversed(coefficients[:-1]):
        result = result * x + c
    return result


def _agx_log_encoding(rgb: torch.Tensor) -> torch.Tensor:
    """``(clamp(log2 x, min_ev, max_ev) - min_ev) / (max_ev - min_ev)``: AgX's log2 shaper onto [0, 1]."""
    ev = torch.log2(rgb.clamp_min(1e-10)).clamp(_AGX_MIN_EV, _AGX_MAX_EV)
    return (ev - _AGX_MIN_EV) / (_AGX_MAX_EV - _AGX_MIN_EV)


def agx(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """Troy Sobotka's AgX base in Benjamin Wrensch's "minimal AgX" form (iolite, 2023), display-linear.

    Inset matrix on linear Rec.709; log2 encoding over ``0.18 · 2^-10 .. 0.18 · 2^6.5``; the
    6th-order polynomial fit of the default-contrast sigmoid; outset matrix; then the display's
    power-2.2 decode (``agxEotf``), so the output is display-linear Rec.709 (negative values, which
    the power leaves undefined, are clamped to 0).

    Examples:
        >>> [round(v, 3) for v in agx(torch.tensor([0.18, 1.0, 5.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.214, 0.59, 0.889]
    """
    encoded = _agx_log_encoding(apply_rows(_AGX_INSET, limited(image)))
    return display(safe_pow(apply_rows(_AGX_OUTSET, _polynomial(encoded, _AGX_SIGMOID)), 2.2), clip)


def agx_godot(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """Godot 4.4's AgX (``tonemap_agx``, ``tonemap.glsl``), an approximation of Blender 4's AgX base.

    Works in Rec.2020 with Blender's rotated inset/outset (folded into one matrix with the primaries
    conversion each way), log2 encoding as :func:`agx`, Godot's own 6th-order sigmoid fit, a power-2.4
    decode *before* the outset, and a display clip; the hue path differs from :func:`agx`.

    Examples:
        >>> [round(v, 3) for v in agx_godot(torch.tensor([0.18, 1.0, 5.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.179, 0.554, 0.854]
    """
    encoded = _agx_log_encoding(apply_rows(_AGX_GODOT_INSET, limited(image)))
    return display(apply_rows(_AGX_GODOT_OUTSET, safe_pow(_polynomial(encoded, _AGX_GODOT_SIGMOID), 2.4)), clip)
