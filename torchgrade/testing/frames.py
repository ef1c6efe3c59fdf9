"""Whole-frame checks: what a per-pixel reference does not see (a frame's edges, its size, its orientation).

A stage that mixes pixels (bloom, a metering mask, a tiled dither) can be right pixel by pixel in the middle of a
frame and wrong at its edges, or at sizes that are not powers of two. Three checks see it:

* :func:`uniform_spread`: a uniform field should stay uniform;
* :func:`turn_error`: a frame mirrored or turned should give the mirrored or turned result (:data:`TURNS`);
* :func:`edge_band_codes`: in 8-bit sRGB codes, how much brighter each edge band of a display frame is than the same
  band of the frame rendered turned by 180° and turned back (a glowing border shows as a positive band).

Examples:
    >>> import torch, torchgrade as tg
    >>> stage = tg.Bloom(mode="scattering", intensity=0.6)
    >>> uniform_spread(stage, (1, 3, 37, 53), 8.0) < 1e-5
    True
    >>> turn_error(stage, torch.rand(1, 3, 37, 53) * 8, "turned") < 1e-5
    True
"""

from __future__ import annotations

from typing import Callable

import torch

from ..color import linear_to_srgb

__all__ = ["TURNS", "turned", "uniform_spread", "turn_error", "edge_bands", "edge_band_codes"]

TURNS = {"mirrored": (-1,), "flipped": (-2,), "turned": (-2, -1)}
"""The dimensions each turn of a frame reverses: left-right, top-bottom, and both (a turn by 180°)."""


def turned(image: torch.Tensor, turn: str) -> torch.Tensor:
    """``image`` mirrored (``"mirrored"``), flipped (``"flipped"``), turned by 180° (``"turned"``) or transposed
    (``"transposed"``, a turn by 90° and a mirror); each is its own inverse.

    Examples:
        >>> turned(torch.arange(4.0).reshape(1, 2, 2), "turned").flatten().tolist()
        [3.0, 2.0, 1.0, 0.0]
    """
    return image.transpose(-1, -2) if turn == "transposed" else image.flip(TURNS[turn])


def uniform_spread(stage: Callable, shape, value: float = 8.0) -> float:
    """``(max - min) / |mean|`` of each channel of ``stage``'s output on a field of ``value`` everywhere, the largest
    over channels and samples: 0 for a stage that keeps a uniform frame uniform (a grade may still tint it).

    Examples:
        >>> uniform_spread(torch.nn.Identity(), (1, 3, 5, 7))
        0.0
    """
    with torch.no_grad():
        planes = stage(torch.full(shape, value)).double().flatten(-2)
    spread = (planes.amax(-1) - planes.amin(-1)) / planes.mean(-1).abs()
    return float(spread.nan_to_num(0.0).max())


def turn_error(stage: Callable, image: torch.Tensor, turn: str) -> float:
    """The largest difference between ``stage`` of ``image`` turned (:func:`turned`), turned back, and ``stage`` of
    ``image``, relative to the largest change the stage makes to ``image`` (or to the output's largest value, where
    the stage changes nothing).

    Examples:
        >>> turn_error(lambda x: x.cumsum(-1), torch.ones(1, 1, 1, 3), "mirrored")  # a running sum is not symmetric
        1.0
    """
    with torch.no_grad():
        out = stage(image).double()
        back = turned(stage(turned(image, turn)), turn).double()
    scale = (out - image.double()).abs().max() if out.shape == image.shape else out.abs().max()
    scale = scale if scale > 0 else out.abs().max()
    return float((back - out).abs().max() / scale) if scale > 0 else 0.0


def edge_bands(values: torch.Tensor, band: int = 16) -> dict:
    """The mean of ``values`` ``(..., H, W)`` over each edge band ``band`` pixels deep: ``{"left", "right", "top",
    "bottom"}``.

    Examples:
        >>> edge_bands(torch.arange(4.0).reshape(1, 4), band=1)["right"]
        3.0
    """
    return {"left": float(values[..., :band].mean()), "right": float(values[..., -band:].mean()),
            "top": float(values[..., :band, :].mean()), "bottom": float(values[..., -band:, :].mean())}


def edge_band_codes(render: Callable, image: torch.Tensor, band: int = 16) -> dict:
    """How much brighter, in 8-bit sRGB codes, each edge band of ``render(image)`` (display-referred linear) is than
    the same band of ``image`` rendered turned by 180° and turned back (:func:`edge_bands`).

    A render that glows along the frame's right edge gives a positive ``"right"`` and a negative ``"left"``: the turned
    render glows along the turned frame's right edge, which turned back is the left one.

    Examples:
        >>> codes = edge_band_codes(lambda x: x.clamp(0, 1), torch.rand(1, 3, 40, 50))
        >>> round(max(abs(v) for v in codes.values()), 6)  # a per-pixel render: no band differs
        0.0
    """
    with torch.no_grad():
        straight = linear_to_srgb(render(image).clamp(0.0, 1.0)) * 255.0
        back = turned(linear_to_srgb(render(turned(image, "turned")).clamp(0.0, 1.0)), "turned") * 255.0
    return edge_bands((straight - back).double(), band)
