"""Reinhard's photographic operators (Reinhard et al. 2002): per channel, with a white point, and on luminance."""

from __future__ import annotations

import torch

from ..base.params import Param, scalar_param
from ..color import luminance
from .base import display, limited

__all__ = ["reinhard", "reinhard_extended", "reinhard_luminance"]


def reinhard(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """Per-channel Reinhard: ``c / (1 + c)`` with ``c = clamp(x, 0, 60)`` (Reinhard et al. 2002, eq. 3).

    Examples:
        >>> reinhard(torch.ones(3, 1, 1)).flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    c = limited(image)
    return display(c / (1.0 + c), clip)


def reinhard_extended(image: torch.Tensor, white_point: Param = 4.0, clip: bool = True) -> torch.Tensor:
    """Per-channel Reinhard with a white point ``w``: ``c (1 + c / w²) / (1 + c)`` (Reinhard 2002, eq. 4).

    ``c`` is clamped to ``[0, w]``: the curve reaches 1 at ``c = w`` and the display clips beyond it.

    Examples:
        >>> reinhard_extended(torch.full((3, 1, 1), 4.0)).flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    w = scalar_param(white_point, image, "white_point")
    c = limited(image, w)
    return display(c * (1.0 + c / (w * w)) / (1.0 + c), clip)


def reinhard_luminance(image: torch.Tensor, white_point: Param = 4.0, clip: bool = True) -> torch.Tensor:
    """Extended Reinhard on luminance, colour scaled to the new luminance (004 notes, ``reinhard_extended_luminance``).

    ``L' = L (1 + L / w²) / (1 + L)`` and ``rgb' = rgb · L' / L``; the ratio ``L'/L = (1 + L/w²) / (1 + L)``
    needs no division by ``L``, so black pixels stay finite. ``L`` is clamped at 0.

    Examples:
        >>> [round(v, 4) for v in reinhard_luminance(torch.ones(3, 1, 1)).flatten().tolist()]  # L = 1: ratio (1 + 1/16) / 2
        [0.5312, 0.5312, 0.5312]
    """
    w = scalar_param(white_point, image, "white_point")
    lum = luminance(image).clamp_min(0.0)
    ratio = (1.0 + lum / (w * w)) / (1.0 + lum)
    return display(image * ratio, clip)
