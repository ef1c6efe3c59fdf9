"""Scene metering for eye adaptation: the frame's mean luminance or log-average (source document 002 resamples
the frame to a power-of-two grid with an exact box filter and averages 2x2 blocks down to one value, which is
the same mean; :func:`area_resize` and :func:`halving_average` are those two steps)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..color import luminance
from ..core import check_choice, check_image, sanitize

__all__ = ["METERING_MODES", "METERING_SIZE", "LOG_DELTA", "area_resize", "halving_average", "meter_luminance"]

METERING_SIZE = 64
"""Side of the square grid the frame is resampled to before the 2x2 averaging (a power of two)."""

LOG_DELTA = 1e-4
"""Reinhard's δ in the log-average ``exp(mean(log(δ + L))) - δ``: keeps black pixels finite."""

METERING_MODES = ("mean", "log")


def _area_weights(size_in, size_out: int, like: torch.Tensor) -> torch.Tensor:
    """``(size_out, size_in)`` box-filter matrix: row ``i`` averages the input pixels under output cell ``i``.

    Output cell ``i`` spans ``[i, i + 1) * size_in / size_out`` in input pixels; each weight is the
    overlap of an input pixel with that span divided by the span, so every row sums to 1 and the
    mean of the output equals the mean of the input exactly, whether it shrinks or enlarges.
    """
    # Positions counted in 1/size_out pixels are integers: in floating point an exported graph run at
    # reduced precision (OpenVINO's bfloat16 default) rounds positions above 256 by whole pixels.
    edges = torch.arange(size_out + 1, device=like.device) * size_in
    pixels = torch.arange(size_in, device=like.device) * size_out
    right = torch.minimum(pixels + size_out, edges[1:, None])
    left = torch.maximum(pixels, edges[:-1, None])
    return (right - left).clamp_min(0).to(like.dtype) / size_in


def area_resize(image: torch.Tensor, size: int) -> torch.Tensor:
    """Resample ``(..., H, W)`` to ``(..., size, size)`` with an exact box (area) filter.

    Two matrix products (rows, then columns), so any ``H, W`` (including 1x1) works and the sizes
    stay symbolic under ONNX export; kornia's antialiased ``resize`` derives its blur kernel from
    the input size with Python numbers, which fixes it to the exported resolution.

    Examples:
        >>> area_resize(torch.arange(6.0).reshape(1, 2, 3), 1).tolist()  # one cell: the mean
        [[[2.5]]]
    """
    rows = _area_weights(image.shape[-2], size, image)
    columns = _area_weights(image.shape[-1], size, image)
    return rows @ image @ columns.transpose(0, 1)


def halving_average(grid: torch.Tensor) -> torch.Tensor:
    """Average 2x2 blocks of a ``(N, C, 2^k, 2^k)`` grid until it is 1x1, as a mip chain does.

    Examples:
        >>> halving_average(torch.arange(16.0).reshape(1, 1, 4, 4)).flatten().tolist()
        [7.5]
    """
    while grid.shape[-1] > 1:
        grid = F.avg_pool2d(grid, 2)
    return grid


def meter_luminance(image: torch.Tensor, metering: str = "log") -> torch.Tensor:
    """Scene luminance of each image of ``(..., 3, H, W)``, shaped ``image.shape[:-3]``.

    The Rec.709 luminance ``L`` (negative values clipped to 0, non-finite pixels sanitized) averaged over the
    frame: ``"mean"`` gives the arithmetic mean of ``L``; ``"log"`` the log-average ``exp(mean(log(δ + L))) - δ``
    (Reinhard et al. 2002, Eq. 1, "the key"), taken per pixel before any averaging so that a few very bright
    pixels barely move it. Unlike Reinhard's form, δ is subtracted again, so a uniform frame meters exactly its
    luminance. The source document's resampling to a 64x64 grid (:func:`area_resize`) and 2x2 averaging down to
    one value (:func:`halving_average`) give this same mean, to rounding: every cell of the grid covers an equal
    area; one reduction computes it without the two matrix products.

    Examples:
        >>> [round(v, 4) for v in meter_luminance(torch.full((2, 3, 8, 8), 0.5), 'mean').tolist()]
        [0.5, 0.5]
    """
    check_image(image)
    check_choice("metering", metering, METERING_MODES)
    return meter_sanitized(sanitize(image), metering)


def meter_sanitized(scene: torch.Tensor, metering: str) -> torch.Tensor:
    """:func:`meter_luminance` of a frame already sanitized (:func:`~torchgrade.core.sanitize`), unchecked.

    For a caller that sanitizes the frame anyway: one pass over it instead of two.

    Examples:
        >>> [round(v, 4) for v in meter_sanitized(torch.full((1, 3, 4, 4), 0.5), 'mean').tolist()]
        [0.5]
    """
    lum = luminance(scene).clamp_min(0)
    if metering == "log":
        lum = torch.log(lum + LOG_DELTA)
    average = lum.mean(dim=(-3, -2, -1))
    if metering == "log":
        average = torch.exp(average) - LOG_DELTA
    return average
