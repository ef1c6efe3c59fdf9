"""The budgets every image a door decodes or makes passes, checked from sizes before anything is allocated.

One pixel budget for all of them (:data:`MAX_PIXELS`): an EXR's data window (:func:`torchgrade.io.read_exr`), a PNG
target (``torchgrade match``), the demo's scene (``torchgrade demo``); a caller that needs more passes its own budget
where the door takes one (``read_exr(max_pixels=...)``, ``grade --max-bytes``). And a bound on the frame-number width
of an output pattern (:data:`MAX_FRAME_DIGITS`), which ``%0900000000d`` would make a 900-million-character name.

Examples:
    >>> check_pixels(20000, 20000, "the demo scene")
    Traceback (most recent call last):
    ...
    ValueError: the demo scene of 20000x20000 pixels is more than the 67108864-pixel budget (8192x8192)
"""

from __future__ import annotations

__all__ = ["MAX_PIXELS", "MAX_FRAME_DIGITS", "check_pixels"]

MAX_PIXELS = 1 << 26
"""Pixels an image may have: 8192x8192 (8K DCI 8192x4320 fits twice). Three float32 channels of that are 805 MB, about
what one frame of a look holds several times over while it is graded."""

MAX_FRAME_DIGITS = 16
"""Widest frame number a file-name pattern may ask for (``%016d``); frame numbers have at most 10 digits."""


def check_pixels(height: int, width: int, what: str, max_pixels: int = MAX_PIXELS) -> None:
    """``ValueError`` naming ``what`` unless ``height`` x ``width`` is positive and within ``max_pixels``."""
    if height < 1 or width < 1:
        raise ValueError(f"{what} must be at least 1x1 pixels, got {width}x{height}")
    if height * width > max_pixels:
        side = int(max_pixels**0.5)
        raise ValueError(f"{what} of {width}x{height} pixels is more than the {max_pixels}-pixel budget ({side}x{side})")
