"""Luminance/chroma (Y, RY, BY) pixels to RGB, as OpenEXR's RGBA interface (ImfRgbaYca) does.

OpenEXR stores RY = (R - Y) / Y and BY = (B - Y) / Y on every second pixel of every second line
(the even coordinates of the data window). Reading them back, the missing chroma samples are
reconstructed with OpenEXR's 27-tap filter, first along the lines that carry chroma, then down the
columns; RGB follows from Y and the weights of the file's chromaticities; and pixels more saturated
than their four diagonal neighbours allow are pulled back towards grey (OpenEXR's ``fixSaturation``).
Every step rounds to half, as OpenEXR's ``Rgba`` pixels do.
"""

from __future__ import annotations

import torch

from .chromaticities import rgb_to_xyz

__all__ = ["luminance_weights", "yca_to_rgb"]

_TAPS = torch.tensor((0.627123, -0.186077, 0.087929, -0.043159, 0.019597, -0.007540, 0.002128))
"""ImfRgbaYca's reconstruction filter: the weights of the chroma samples 1, 3, ..., 13 pixels away."""


def luminance_weights(chromaticities) -> torch.Tensor:
    """The RGB -> Y weights of a file (OpenEXR's ``computeYw``), summing to 1.

    Examples:
        >>> [round(w, 4) for w in luminance_weights(((0.64, 0.33), (0.3, 0.6), (0.15, 0.06), (0.3127, 0.329))).tolist()]
        [0.2126, 0.7152, 0.0722]
    """
    row = rgb_to_xyz(chromaticities)[1]
    return (row / row.sum()).float()


def _half(values: torch.Tensor) -> torch.Tensor:
    return values.half().float()


def _upsample(samples: torch.Tensor, length: int, before: int = 0) -> torch.Tensor:
    """Fill in the odd positions 0..length-1 (and ``before`` = 1: position -1) along dim 0, in half.

    Samples past either end repeat the end sample, as OpenEXR pads its line buffers.
    """
    taps = len(_TAPS)
    padded = torch.cat((samples[:1].expand(taps, *samples.shape[1:]), samples, samples[-1:].expand(taps, *samples.shape[1:])))
    count = length // 2 + before
    odd = torch.zeros((count,) + samples.shape[1:])
    start = taps - before  # padded index of the sample just below the first odd position
    weights = _TAPS.tolist()
    # in place, one tap at a time (no temporaries), summed in OpenEXR's order: farthest below first
    for offset, weight in [(-d, w) for d, w in reversed(list(enumerate(weights)))] + [(1 + d, w) for d, w in enumerate(weights)]:
        odd.add_(padded[start + offset:start + offset + count], alpha=weight)
    result = samples.new_empty((length + before,) + samples.shape[1:], dtype=torch.float16)
    result[before::2] = samples[: (length + 1) // 2]
    result[1 - before::2] = odd
    return result


def _to_rgb(y: torch.Tensor, ry: torch.Tensor, by: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    red, blue = (ry + 1) * y, (by + 1) * y
    green = (y - red * weights[0] - blue * weights[2]) / weights[1]
    grey = (ry == 0) & (by == 0)
    return _half(torch.stack([torch.where(grey, y, c) for c in (red, green, blue)]))


def _saturation(rgb: torch.Tensor) -> torch.Tensor:
    high, low = rgb.amax(dim=0), rgb.amin(dim=0)
    return torch.where(high > 0, 1 - low / high.where(high > 0, 1), 0)


def _fix_saturation(rgb: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Desaturate pixels of rows 1..-2 of ``rgb`` more saturated than their diagonal neighbours."""
    saturation = _saturation(rgb)
    padded = torch.cat((saturation[:, :1], saturation, saturation[:, -1:]), dim=1)
    mean = 0.25 * (padded[:-2, :-2] + padded[:-2, 2:] + padded[2:, :-2] + padded[2:, 2:])
    ceiling = 1 - (1 - mean.clamp(max=1)) * 0.25
    centre, own = rgb[:, 1:-1], saturation[1:-1]
    factor = ceiling / own.where(own > 0, 1)
    high = centre.amax(dim=0)
    pulled = (high - (high - centre) * factor).clamp(min=0)
    before, after = (torch.einsum("c,chw->hw", weights, t) for t in (centre, pulled))
    pulled = torch.where(after > 0, pulled * (before / after.where(after > 0, 1)), pulled)
    return torch.where(own > ceiling, _half(pulled), centre)


def _extended_rows(height: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Which Y row and which reconstructed chroma row make each of the rows -1..height.

    As OpenEXR's line buffers: the row above the top repeats row 0's luminance with chroma
    filtered at row -1; the row below the bottom is row height-2 (the last row that carries chroma
    when the height is even).
    """
    below = max(height - 2, 0)
    luma = torch.cat((torch.tensor([0]), torch.arange(height), torch.tensor([below])))
    chroma = torch.cat((torch.arange(height + 1), torch.tensor([below + 1])))
    return luma, chroma


def yca_to_rgb(y, ry, by, weights: torch.Tensor, lines_per_strip: int = 32) -> torch.Tensor:
    """RGB ``(3, H, W)`` from full-resolution Y and 2×2-subsampled RY, BY ``(H/2, W/2)``.

    ``weights`` are the file's luminance weights (:func:`luminance_weights`). The result is float16:
    every value is a half, as OpenEXR's. Chroma is reconstructed in half, then RGB computed
    ``lines_per_strip`` lines at a time, so the temporaries stay a fraction of the image.

    Examples:
        >>> rgb = yca_to_rgb(torch.ones(4, 4), torch.zeros(2, 2), torch.full((2, 2), 0.5), torch.tensor((0.2126, 0.7152, 0.0722)))
        >>> rgb[:, 0, 0].tolist()  # R = Y, B = 1.5 Y, G what keeps Y; rounded to half
        [1.0, 0.94970703125, 1.5]
    """
    y = torch.as_tensor(y).half()
    height, width = y.shape
    chroma = torch.stack((torch.as_tensor(ry).float(), torch.as_tensor(by).float()), dim=-1)
    chroma = _upsample(_upsample(chroma.transpose(0, 1), width).transpose(0, 1), height, before=1)
    luma_rows, chroma_rows = _extended_rows(height)
    image = torch.empty(3, height, width, dtype=torch.float16)
    for top in range(0, height, lines_per_strip):
        bottom = min(top + lines_per_strip, height)
        strip = slice(top, bottom + 2)  # extended rows top-1 .. bottom
        part = chroma[chroma_rows[strip]].float()
        rgb = _to_rgb(y[luma_rows[strip]].float(), part[..., 0], part[..., 1], weights)
        image[:, top:bottom] = _fix_saturation(rgb, weights)
    return image
