"""Extreme inputs every stage is tested on: the sample images' own extremes and the float edges."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import torch

from ..io import read_exr

__all__ = ["EXTREME_VALUES", "extreme_inputs", "SWEEP_MIXES", "sweep_values", "sweep_frame", "NEAR_BLACK"]

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


SWEEP_MIXES = (1.0, 0.18)
"""The values a swept value is mixed with in a pixel (:func:`sweep_frame`): white and grey."""

NEAR_BLACK = 1e-2
"""A pixel is near black when no channel's magnitude passes this (the sweep's pixels from 0 to 1e-2 in every channel)."""


def sweep_values(dtype: torch.dtype) -> tuple:
    """0, every power of ten that ``dtype`` holds (from the first that does not round to 0: float32's 1e-45,
    float16's 1e-7, bfloat16's 1e-40) and its largest finite value.

    Examples:
        >>> values = sweep_values(torch.float32)
        >>> values[:3], values[-2:], len(values)
        ((0.0, 1e-45, 1e-44), (1e+38, 3.4028234663852886e+38), 86)
        >>> sweep_values(torch.float16)[1], sweep_values(torch.float16)[-1]
        (1e-07, 65504.0)
    """
    info = torch.finfo(dtype)
    smallest = info.smallest_normal * info.eps  # the smallest denormal; half of it rounds to 0
    low, high = math.ceil(math.log10(smallest / 2)), math.floor(math.log10(info.max))
    return (0.0, *(float(f"1e{power}") for power in range(low, high + 1)), float(info.max))


def sweep_frame(dtype: torch.dtype, negatives: bool = True) -> torch.Tensor:
    """Every value of :func:`sweep_values` in every kind of pixel, as one ``(1, 3, values, kinds)`` frame of ``dtype``.

    Each row is one value ``v``; its columns the pixels ``(v, 0, 0)``, ``(0, v, 0)``, ``(0, 0, v)`` (single
    channels), ``(v, v, v)`` (grey) and ``v`` mixed with :data:`SWEEP_MIXES` in each channel (``(v, 1, 0.18)`` and its
    rotations), then with ``negatives`` the same seven with ``-v``: one frame, so a stage runs the whole sweep at once.

    Examples:
        >>> frame = sweep_frame(torch.float32)
        >>> frame.shape, frame[0, :, 1, 4].tolist(), frame[0, :, 1, 7].tolist()
        (torch.Size([1, 3, 86, 14]), [1.401298464324817e-45, 1.0, 0.18000000715255737], [-1.401298464324817e-45, 0.0, 0.0])
    """
    white, grey = SWEEP_MIXES

    def kinds(v: float) -> list:
        single = [[v if channel == c else 0.0 for channel in range(3)] for c in range(3)]
        mixed = [[v, white, grey], [grey, v, white], [white, grey, v]]
        return single + [[v, v, v]] + mixed

    rows = [kinds(v) + (kinds(-v) if negatives else []) for v in sweep_values(dtype)]
    return torch.tensor(rows, dtype=torch.float64).permute(2, 0, 1).unsqueeze(0).to(dtype)
