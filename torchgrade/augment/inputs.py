"""What ``RandomPostFX`` takes: display-referred sRGB inputs are images in [0, 1], checked before they are decoded; a
look LUT given as a stage, its config or its LUT."""

from __future__ import annotations

import torch

from ..output.layer import LookLUT

__all__ = ["SRGB_TOLERANCE", "check_srgb_peak", "look_stage"]


SRGB_TOLERANCE = 1e-3
"""How far above 1 an sRGB input may reach (rounding of an earlier step) before it is refused as 0..255 data."""


def check_srgb_peak(name: str, peak: torch.Tensor) -> None:
    """Refuse an sRGB input whose largest value ``peak`` is above 1 (0..255 data, most likely).

    Examples:
        >>> check_srgb_peak("images", torch.tensor(255.0))
        Traceback (most recent call last):
        ...
        ValueError: input_space="srgb" takes images in [0, 1], got values up to 255: divide 0..255 images by 255
    """
    if float(peak) > 1.0 + SRGB_TOLERANCE:
        raise ValueError(f'input_space="srgb" takes images in [0, 1], got values up to {float(peak):g}: divide 0..255 images by 255')


def look_stage(look_lut) -> LookLUT | None:
    """``RandomPostFX``'s ``look_lut`` as a stage: a ``LookLUT``, a dict of its arguments (a config's), or its ``lut``."""
    if look_lut is None or isinstance(look_lut, LookLUT):
        return look_lut
    return LookLUT.from_config(look_lut) if isinstance(look_lut, dict) else LookLUT(look_lut)
