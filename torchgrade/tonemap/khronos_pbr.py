"""Khronos PBR Neutral (Khronos 3D Commerce): a tone mapper that keeps base colours below its shoulder as they are."""

from __future__ import annotations

import torch

from ..base.planes import channel_max, channel_min
from .base import display, limited

__all__ = ["khronos_pbr_neutral"]

_KHRONOS_F90 = 0.04
_KHRONOS_START_COMPRESSION = 0.8 - _KHRONOS_F90
_KHRONOS_DESATURATION = 0.15


def khronos_pbr_neutral(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """Khronos PBR Neutral (Khronos 3D Commerce reference GLSL, ``PBRNeutralToneMapping``).

    Offset ``x - 6.25 x²`` below ``x = min(rgb) = 0.08``, else F90 = 0.04, subtracted from every
    channel; then where ``peak = max(rgb) ≥ Ks = 0.76``: scale to ``newPeak = 1 - d² / (peak + d - Ks)``
    (``d = 1 - Ks``) and mix towards ``newPeak`` grey by ``g = 1 - 1 / (Kd (peak - newPeak) + 1)``,
    Kd = 0.15. Below ``Ks`` colours pass through after the offset.

    Examples:
        >>> [round(v, 3) for v in khronos_pbr_neutral(torch.full((3, 1, 1), 0.5)).flatten().tolist()]
        [0.46, 0.46, 0.46]
    """
    c = limited(image)
    low = channel_min(c)
    c = c - torch.where(low < 0.08, low - 6.25 * low * low, _KHRONOS_F90)
    peak = channel_max(c)
    compressing = peak.clamp_min(_KHRONOS_START_COMPRESSION)
    d = 1.0 - _KHRONOS_START_COMPRESSION
    new_peak = 1.0 - d * d / (compressing + d - _KHRONOS_START_COMPRESSION)
    scaled = c * (new_peak / compressing)
    g = 1.0 - 1.0 / (_KHRONOS_DESATURATION * (compressing - new_peak) + 1.0)
    compressed = scaled + g * (new_peak - scaled)
    return display(torch.where(peak < _KHRONOS_START_COMPRESSION, c, compressed), clip)
