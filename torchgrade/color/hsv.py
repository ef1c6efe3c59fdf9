"""RGB <-> HSV (hue in turns), exact and with finite gradients at grey and black."""

from __future__ import annotations

import torch

from ..base.planes import channel_max, channel_min
from ..runtime import affine, constant, where
from .spaces import CHANNEL

__all__ = [
    "rgb_to_hsv", "hsv_to_rgb", "hsv_planes", "rgb_from_hsv_planes", "rgb_planes_from_hsv",
]

_HUE_OFFSETS = (1.0, 5.0 / 3.0, 4.0 / 3.0)
"""Unity ``HsvToRgb``'s ``K.xyz`` (0, 2/3, 1/3) plus 1, one a channel: ``frac`` of a positive number."""


def rgb_to_hsv(image: torch.Tensor) -> torch.Tensor:
    """RGB -> HSV with hue in turns [0, 1), for non-negative RGB.

    The exact hexcone model (Smith 1978): ``V = max``, ``S = (max - min) / max``, hue from the
    dominant channel. Unlike Unity's ``RgbToHsv`` there is no ``1e-4`` bias, so HSV round trips are
    exact; at grey (undefined hue) and black (undefined saturation) hue and saturation are 0 and
    their gradients are finite.

    Examples:
        >>> orange = torch.tensor([1.0, 0.5, 0.0]).reshape(1, 3, 1, 1)
        >>> [round(v, 4) for v in rgb_to_hsv(orange).flatten().tolist()]
        [0.0833, 1.0, 1.0]
    """
    return torch.cat(hsv_planes(image), dim=CHANNEL)


def hsv_planes(image: torch.Tensor) -> tuple:
    """:func:`rgb_to_hsv` as its three planes ``(hue, saturation, value)``, each ``(..., 1, H, W)``: for a caller that
    changes a plane and goes back (:func:`rgb_from_hsv_planes`), with no frame joined or split. ``image`` may be given
    as its three planes (a tuple).

    Examples:
        >>> [round(float(v), 4) for v in hsv_planes(torch.tensor([1.0, 0.5, 0.0]).reshape(3, 1, 1))]
        [0.0833, 1.0, 1.0]
    """
    r, g, b = image if isinstance(image, tuple) else image.split(1, dim=CHANNEL)
    value = channel_max(image)
    delta = value - channel_min(image)
    chromatic = delta > 0
    safe_delta = where(chromatic, delta, 1.0)
    hue_r = torch.remainder((g - b) / safe_delta, 6.0)
    hue_g = (b - r) / safe_delta + 2.0
    hue_b = (r - g) / safe_delta + 4.0
    # the first channel at the maximum, as argmax takes it, without argmax's indices (8 bytes a pixel)
    hue = torch.where(r == value, hue_r, torch.where(g == value, hue_g, hue_b)) / 6.0
    hue = where(chromatic, hue, 0.0)
    lit = value > 0
    saturation = where(lit, delta / where(lit, value, 1.0), 0.0)
    return hue, saturation, value


def hsv_to_rgb(image: torch.Tensor) -> torch.Tensor:
    """HSV (hue in turns) -> RGB: ``V * lerp(1, clamp(|frac(H + k) * 6 - 3| - 1, 0, 1), S)`` (Unity ``HsvToRgb``).

    Examples:
        >>> red = torch.tensor([0.0, 1.0, 2.0]).reshape(1, 3, 1, 1)  # hue 0, saturation 1, value 2
        >>> [round(v, 4) for v in hsv_to_rgb(red).flatten().tolist()]
        [2.0, 0.0, 0.0]
    """
    return rgb_from_hsv_planes(*image.split(1, dim=CHANNEL))


def rgb_from_hsv_planes(hue: torch.Tensor, saturation: torch.Tensor, value: torch.Tensor) -> torch.Tensor:
    """:func:`hsv_to_rgb` of the three ``(..., 1, H, W)`` planes of :func:`hsv_planes`.

    Examples:
        >>> rgb_from_hsv_planes(*(torch.tensor([[[v]]]) for v in (0.0, 1.0, 2.0))).flatten().tolist()
        [2.0, 0.0, 0.0]
    """
    return _from_ramp(value, saturation, _ramp_less_one(hue, constant(_HUE_OFFSETS, value).reshape(3, 1, 1)))


def rgb_planes_from_hsv(hue: torch.Tensor, saturation: torch.Tensor, value: torch.Tensor) -> tuple:
    """:func:`rgb_from_hsv_planes` returned as the three planes ``(r, g, b)``: the form of a chain computed on planes
    (:func:`~torchgrade.runtime.strips.pixelwise`), each channel's offset a number in the kernel.

    Examples:
        >>> [float(p) for p in rgb_planes_from_hsv(*(torch.tensor(v) for v in (0.0, 1.0, 2.0)))]
        [2.0, 0.0, 0.0]
    """
    return tuple(_from_ramp(value, saturation, _ramp_less_one(hue, offset)) for offset in _HUE_OFFSETS)


def _ramp_less_one(hue: torch.Tensor, offset) -> torch.Tensor:
    """Unity's ``saturate(|frac(H + K) · 6 - 3| - 1)`` less one, in one clamp: ``clamp(|6 frac(H + k) - 3| - 2, -1, 0)``."""
    return (torch.abs(affine(torch.frac(hue + offset), 6.0, -3.0)) - 2.0).clamp(-1.0, 0.0)


def _from_ramp(value: torch.Tensor, saturation: torch.Tensor, ramp_less_one: torch.Tensor) -> torch.Tensor:
    """``V lerp(1, ramp, S)`` as ``V + (V S)(ramp - 1)``: exact at S = 0, ramp = 1 and S = 1, ramp = 0."""
    return torch.addcmul(value, value * saturation, ramp_less_one)
