"""What a row of the suite is (:class:`Method`) and how rows are named. Part of
``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import torch

import torchgrade as tg

__all__ = ["Method", "lut_name", "default_name", "lut_info"]


@dataclass
class Method:
    """One row: a way to compute the per-pixel stage (or the whole look, ``whole_look=True``).

    ``apply`` maps the row's input (what the per-pixel stage receives, or the scene for a whole-look row) in
    ``dtype`` to display-referred linear RGB. ``timer(frame)`` returns ``(run, reset)``: the timed call and an
    untimed call to run before each one (or ``None``); by default ``run`` is ``apply(frame)``.
    ``host`` rows run on the CPU whatever the device (onnxruntime, OpenVINO, OpenColorIO). ``headline``: a row a
    choice hangs on, which the performance page shows (not one of the full run's grid). ``info`` goes into the row's
    record.
    """

    name: str
    family: str
    apply: Callable[[torch.Tensor], torch.Tensor]
    dtype: torch.dtype = torch.float32
    whole_look: bool = False
    host: bool = False
    timer: Optional[Callable] = None
    info: dict = field(default_factory=dict)
    headline: bool = True

    def timed_call(self, frame: torch.Tensor):
        return self.timer(frame) if self.timer else ((lambda: self.apply(frame)), None)


def lut_name(size: int, shaper: str, interpolation: str) -> str:
    """Examples:
        >>> lut_name(33, "logc", "tetrahedral")
        'LUT 33³ logc tetrahedral'
    """
    return f"LUT {size}³ {shaper} {interpolation}"


def default_name(lut: tg.LUT3D, interpolation: str, form: Optional[str] = None) -> str:
    """The name of a row of the default bake ``lut``: its size and lattice as baked, the interpolation and CPU form."""
    return f"{lut_name(lut.size, lut.shaper, interpolation)}, default bake" + (f", {form}" if form else "")


def lut_info(lut: tg.LUT3D, interpolation: str, **more) -> dict:
    """A LUT row's record fields: size, lattice, interpolation, and ``more``."""
    return {"lut_size": lut.size, "shaper": lut.shaper, "interpolation": interpolation, **more}
