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

from ...runtime.policy import one_thread
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


def _window(samples: torch.Tensor, low: int, high: int) -> torch.Tensor:
    """Samples ``low``..``high - 1`` along dim 0, the end samples repeating past either end (as OpenEXR pads its line buffers)."""
    return samples.index_select(0, torch.arange(low, high).clamp(0, len(samples) - 1))


def _filtered(window: torch.Tensor, low: int, first: int, count: int) -> torch.Tensor:
    """The ``count`` odd positions from the one between samples ``first - 1`` and ``first``, filtered in float32.

    ``window`` holds the samples from ``low`` on. Summed in place, one tap at a time (no temporaries
    but the window in float32), in OpenEXR's order: farthest below first.
    """
    odd = torch.zeros((count,) + window.shape[1:])
    window = window.float()
    at = first - 1 - low  # window index of the sample just below the first odd position
    weights = _TAPS.tolist()
    for offset, weight in [(-d, w) for d, w in reversed(list(enumerate(weights)))] + [(1 + d, w) for d, w in enumerate(weights)]:
        odd.add_(window[at + offset:at + offset + count], alpha=weight)
    return odd


def _upsample(samples: torch.Tensor, length: int) -> torch.Tensor:
    """Fill in the odd positions 0..length-1 along dim 0, in half."""
    taps = len(_TAPS)
    result = samples.new_empty((length,) + samples.shape[1:], dtype=torch.float16)
    result[0::2] = samples[: (length + 1) // 2]
    result[1::2] = _filtered(_window(samples, -taps, len(samples) + taps), -taps, 1, length // 2)
    return result


def _chroma_rows(chroma: tuple, width: int, first: int, stop: int) -> torch.Tensor:
    """Full-resolution chroma ``(rows, width, 2)`` of rows ``first``..``stop - 1`` (row -1 included), in half.

    ``chroma`` is the two sample planes ``(RY, BY)``. Only the sample lines these rows need are taken
    (side by side) and filtered along the line; then even rows are those lines (row ``2 j`` is line
    ``j``) and odd rows ``2 k - 1`` are filtered down the columns from the lines around.
    """
    low = first // 2 - len(_TAPS) - 1
    samples = torch.stack([_window(plane, low, stop // 2 + len(_TAPS) + 1) for plane in chroma], dim=-1)
    lines = _upsample(samples.transpose(0, 1), width).transpose(0, 1)
    rows = torch.empty((stop - first, width, 2), dtype=torch.float16)
    odd_first = first + (first % 2 == 0)  # odd rows: -1, 1, 3, ...
    even_first = first + (first % 2 != 0)
    rows[odd_first - first::2] = _filtered(lines, low, (odd_first + 1) // 2, len(range(odd_first, stop, 2)))
    rows[even_first - first::2] = lines[even_first // 2 - low:][:len(range(even_first, stop, 2))]
    return rows


def _to_rgb(y: torch.Tensor, ry: torch.Tensor, by: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    red, blue = (ry + 1) * y, (by + 1) * y
    green = (y - red * weights[0] - blue * weights[2]) / weights[1]
    grey = (ry == 0) & (by == 0)
    return _half(torch.stack([torch.where(grey, y, c) for c in (red, green, blue)]))


def _luminance(rgb: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """``Y = wr R + wg G + wb B`` of ``(3, H, W)`` pixels, summed in that order (OpenEXR's ``Yw`` dot product)."""
    return rgb[0] * weights[0] + rgb[1] * weights[1] + rgb[2] * weights[2]


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
    before, after = (_luminance(t, weights) for t in (centre, pulled))
    pulled = torch.where(after > 0, pulled * (before / after.where(after > 0, 1)), pulled)
    return torch.where(own > ceiling, _half(pulled), centre)


def yca_to_rgb(y, ry, by, weights: torch.Tensor, out: torch.Tensor | None = None, lines_per_strip: int | None = None) -> torch.Tensor:
    """RGB ``(3, H, W)`` from full-resolution Y and 2×2-subsampled RY, BY ``(H/2, W/2)``.

    ``weights`` are the file's luminance weights (:func:`luminance_weights`). Every value is a half, as
    OpenEXR's: the result is float16, or written into ``out`` (any float dtype). Chroma is
    reconstructed and turned into RGB ``lines_per_strip`` lines at a time, so no temporary holds more
    than a strip: the memory is the samples, the result, and about 40 float32 planes of a strip's
    lines: on a 406x610 image each line of a strip added about 0.04x of the result to the peak (1.34x
    with 4-line strips, 1.50x with 8, 1.67x with 16, in one process). So by default a strip is 1/256
    of the height, between 4 and 32 lines; the output does not depend on it. The strips run on one
    CPU thread, as OpenEXR reconstructs its lines: strip-sized operations split over two threads
    waited on each other whenever the cores were busy (the CPU time column of
    ``benchmarks/results/exr_memory.md``).

    Examples:
        >>> rgb = yca_to_rgb(torch.ones(4, 4), torch.zeros(2, 2), torch.full((2, 2), 0.5), torch.tensor((0.2126, 0.7152, 0.0722)))
        >>> rgb[:, 0, 0].tolist()  # R = Y, B = 1.5 Y, G what keeps Y; rounded to half
        [1.0, 0.94970703125, 1.5]
    """
    y = torch.as_tensor(y).half()
    height, width = y.shape
    chroma = (torch.as_tensor(ry).half(), torch.as_tensor(by).half())  # the caller's half arrays, not copied
    image = torch.empty(3, height, width, dtype=torch.float16) if out is None else out
    lines_per_strip = lines_per_strip or min(32, max(4, height // 256))
    with one_thread():
        for top in range(0, height, lines_per_strip):
            _strip_to_rgb(y, chroma, weights, image, top, min(top + lines_per_strip, height))
    return image


def _strip_to_rgb(y: torch.Tensor, chroma: tuple, weights: torch.Tensor, image: torch.Tensor, top: int, bottom: int) -> None:
    """Rows ``top``..``bottom - 1`` of :func:`yca_to_rgb`, written into ``image``."""
    height, width = y.shape
    # rows top-1 .. bottom, as OpenEXR's line buffers: the row above the top repeats row 0's luminance
    # with the chroma of row -1; the row below the bottom is row height-2 (the last row that carries
    # chroma when the height is even)
    luma_rows = torch.arange(top - 1, bottom + 1).clamp(min=0)
    chroma_rows = torch.arange(top - 1, bottom + 1)
    if bottom == height:
        luma_rows[-1] = chroma_rows[-1] = max(height - 2, 0)
    first = int(chroma_rows.min())
    part = _chroma_rows(chroma, width, first, int(chroma_rows.max()) + 1).index_select(0, chroma_rows - first).float()
    rgb = _to_rgb(y.index_select(0, luma_rows).float(), part[..., 0], part[..., 1], weights)
    image[:, top:bottom] = _fix_saturation(rgb, weights)
