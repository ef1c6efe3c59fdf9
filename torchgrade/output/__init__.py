"""The display-referred end of a look: a creative LUT after tone mapping (:func:`look_lut`), deband dither
(:func:`dither`), display encodings (:func:`encode_display`), and their stages (:mod:`.layer`).

Examples:
    >>> import torch
    >>> from torchgrade.output import Display
    >>> Display("srgb")(torch.full((1, 3, 1, 1), 0.18)).flatten()[0].item() > 0.46
    True
"""

from .display import (
           DISPLAY_ENCODINGS,
           DISPLAY_PRESETS,
           DISPLAY_PRIMARIES,
           encode_display,
)
from .dither import dither, dither_pattern
from .layer import Display, Dither, LookLUT
from .look_lut import LOOK_ENCODINGS, look_lut, read_lut_file

__all__ = ["LookLUT", "Dither", "Display", "look_lut", "read_lut_file", "dither", "dither_pattern", "encode_display",
           "LOOK_ENCODINGS", "DISPLAY_ENCODINGS", "DISPLAY_PRESETS", "DISPLAY_PRIMARIES"]
