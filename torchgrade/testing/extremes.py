"""Extreme inputs every stage is tested on: the sample images' own extremes and the float edges."""

from __future__ import annotations

import itertools
from pathlib import Path

import torch

from ..io import read_exr

__all__ = ["EXTREME_VALUES", "extreme_inputs"]

EXTREME_VALUES = (0.0, 1e-45, 1e-38, 1e-8, 0.18, 1.0, 59.9, 60.0, 1e3, 65504.0, 1e30, 3e38)
"""Per-channel values every stage must survive: black, float32's smallest denormal and normal, grey, white,
Reinhard's 60 in half precision, half's largest, and values only float32 holds."""


def extreme_inputs(sample_dir) -> dict[str, torch.Tensor]:
    """The input families every stage is checked on, as float64 ``(1, 3, H, W)`` images.

    From the OpenEXR sample images in ``sample_dir``: all 65,536 half values (``AllHalfValues.exr``:
    NaN, ±Inf, denormals, negatives), ``WideFloatRange.exr`` (±1e38) and ``WideColorGamut.exr``
    (negative out-of-gamut RGB), the last two at every fourth pixel; then every combination of
    three :data:`EXTREME_VALUES`, and black, grey and 3e38 frames.

    Examples:
        >>> from pathlib import Path
        >>> import torchgrade
        >>> families = extreme_inputs(Path(torchgrade.__file__).parents[2] / "shared" / "data" / "exr")
        >>> families["value-grid"].shape, families["all-half-values"].numel() // 3
        (torch.Size([1, 3, 36, 48]), 65536)
    """

    def sample(name: str, step: int) -> torch.Tensor:
        return read_exr(Path(sample_dir) / name)[:3, ::step, ::step].unsqueeze(0).double()

    grid = torch.tensor(list(itertools.product(EXTREME_VALUES, repeat=3)), dtype=torch.float64).T.reshape(1, 3, 36, 48)
    return {
        "all-half-values": sample("AllHalfValues.exr", 1),
        "wide-float-range": sample("WideFloatRange.exr", 4),
        "wide-color-gamut": sample("WideColorGamut.exr", 4),
        "value-grid": grid,
        "black": torch.zeros(1, 3, 16, 16, dtype=torch.float64),
        "constant": torch.full((1, 3, 16, 16), 0.18, dtype=torch.float64),
        "constant-huge": torch.full((1, 3, 16, 16), 3e38, dtype=torch.float64),
    }
