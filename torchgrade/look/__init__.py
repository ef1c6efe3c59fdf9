"""The whole look: its slots in the order they run (:data:`SLOTS`, :mod:`.slots`) and :class:`PostFX` (:mod:`.postfx`).

Examples:
    >>> from torchgrade.look import SLOTS
    >>> [slot.name for slot in SLOTS]
    ['exposure', 'bloom', 'grade', 'primary', 'tonemap', 'lut', 'look_lut', 'dither', 'display']
"""

from .postfx import PostFX
from .slots import SLOTS, STAGES, Slot, build_stage

__all__ = ["PostFX", "SLOTS", "STAGES", "Slot", "build_stage"]
