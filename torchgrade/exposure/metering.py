"""Scene metering for eye adaptation: the frame's mean luminance, its log-average, or the average of a
percentile band of its histogram, each weighted by a metering mask (the whole frame, centre-weighted, a spot
or a mask of the user's).

Source document 002 resamples the frame to a power-of-two grid with an exact box filter and averages 2x2
blocks down to one value, which is the same mean; :func:`area_resize` and :func:`halving_average` are those
two steps. The histogram and the masks follow Unity HDRP's Exposure override (Automatic Histogram, metering
modes Center Weighted and Spot) and Bevy's ``AutoExposure`` (the metering-mask texture).
"""

from __future__ import annotations

import math
from typing import Optional

import torch
import torch.nn.functional as F

from ..base.images import check_image, sanitize
from ..base.params import check_choice
from ..color import luminance
from ..runtime import constant, device_cached

__all__ = ["METERING_MODES", "METERING_MASKS", "METERING_SIZE", "LOG_DELTA", "HISTOGRAM_TABLES", "HISTOGRAM_BINS", "HISTOGRAM_RANGE",
           "HISTOGRAM_BLOCK", "SPOT_RADIUS", "area_resize", "halving_average", "meter_luminance", "metering_weights",
           "histogram_band_average", "block_stops"]

METERING_SIZE = 64
"""Side of the square grid the frame is resampled to before the 2x2 averaging (a power of two)."""

LOG_DELTA = 1e-4
"""Reinhard's δ in the log-average ``exp(mean(log(δ + L))) - δ``: keeps black pixels finite."""

METERING_MODES = ("mean", "log", "histogram")

METERING_MASKS = ("average", "center", "spot")
"""The built-in metering masks; a 2-D tensor of weights is the fourth kind (HDRP's Mask Weighted, Bevy's mask)."""

HISTOGRAM_TABLES = 8
"""Tables a histogram is counted into, image column ``c`` into table ``c mod 8``, the tables summed after. Neighbouring
pixels of a frame mostly fall in one bin: counted into one table, each addition waits for the one before it at the
same address (on a CPU, a chain of dependent additions; on a GPU, atomic additions of a warp's threads to one address:
a 4K frame's histogram took 13.19 ms on an H200, ``benchmarks/results/gpu.md``, run D). Eight neighbouring columns
in eight tables of 128 bins (4 KiB, in a CPU core's first-level cache) break that chain (the exposure stage 0.86 and
0.65 of one table's time, ``benchmarks/results/cpu_paths.md``); a table per column, which a GPU's threads would
never share, would not fit that cache (1920 tables of 128 bins at 1080p)."""

HISTOGRAM_BINS = 128
"""Bins of the luminance histogram, as in HDRP's ``HISTOGRAM_BINS``."""

HISTOGRAM_RANGE = (-8.0, 8.0)
"""Stops around middle grey the histogram spans when no limits are set: Bevy's default 16-stop range."""

HISTOGRAM_BLOCK = 1
"""Side of the square blocks of pixels the histogram counts, one value a block: by default 1, every pixel. 2 counts a
quarter of the values, as the engines meter a reduced frame, but its blocks start at the frame's top left corner, so
at an odd side the edge that cuts them is the right or bottom one, and a flipped or turned frame meters other blocks
(``tests/library/test_whole_frames.py`` holds the default to turned frames). A block's value is the area mean of its pixels' stops (each clamped to the histogram's range
first), the log-average of its luminance: averaging the luminance itself (a box filter of the frame) blends a block's
darks into its lights and moves the band the histogram averages (Desk 0.12 stops at 2x2 blocks, centre-weighted),
where the stops' mean keeps the metering of the five sample photographs within 0.05 stops of counting every pixel
with every mask (``tests/exposure/test_exposure_metering.py``; the figures in ``docs/exposure.md``). 1 counts every
pixel; larger blocks count fewer and move it further (4x4 blocks moved the spot metering of Garden 0.096 stops)."""

SPOT_RADIUS = 0.075
"""HDRP's spot metering radius, as a fraction of half the frame's width plus height."""


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


def metering_weights(mask, like: torch.Tensor) -> Optional[torch.Tensor]:
    """The weight of each pixel of ``like`` (``(..., H, W)``) in the metering, ``(H, W)``; ``None`` for ``"average"``.

    With ``d`` a pixel's distance from the frame's centre and ``s = (W + H) / 2``, both in pixels (HDRP's
    ``ExposureCommon.hlsl``):

    * ``"center"``: ``1 - saturate(d / s)``, weight 1 at the centre falling to 0 at the corners' distance;
    * ``"spot"``: ``1 - saturate(d - SPOT_RADIUS * s)``, a disc of radius 7.5 % of ``s`` with a one-pixel edge;
    * a 2-D tensor of non-negative weights: resampled to the frame (bilinear, as a texture is sampled) and divided by
      its largest weight, so that weights of any finite size (1e37 made every output NaN) sum within range. Where it
      leaves the frame no weight at all, the frame is metered as ``"average"`` (every weight 1).

    Examples:
        >>> weights = metering_weights("center", torch.zeros(3, 3, 5))
        >>> round(weights[1, 2].item(), 3), round(weights[0, 0].item(), 3)  # centre pixel, corner pixel
        (1.0, 0.441)
    """
    if isinstance(mask, str) and mask == "average":
        return None
    if isinstance(mask, torch.Tensor):
        resampled = F.interpolate(mask.to(like)[None, None], size=like.shape[-2:], mode="bilinear", align_corners=False)[0, 0]
        weights = resampled.clamp_min(0)
        weights = weights / weights.amax().clamp_min(torch.finfo(weights.dtype).tiny)
        return weights + (weights.sum() <= 0).to(weights)
    check_choice("metering_mask", mask, METERING_MASKS)
    return _shaped_weights(mask, like.shape[-2], like.shape[-1], like.dtype, like.device)


@device_cached
def _shaped_weights(mask: str, height, width, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """The ``"center"`` or ``"spot"`` weights of an ``height x width`` frame (:func:`metering_weights`), made once a size."""
    rows = torch.arange(height, device=device, dtype=dtype) + (0.5 - height / 2)
    columns = torch.arange(width, device=device, dtype=dtype) + (0.5 - width / 2)
    distance = torch.sqrt(rows[:, None] * rows[:, None] + columns * columns)
    half_extent = (height + width) / 2
    falloff = distance / half_extent if mask == "center" else distance - SPOT_RADIUS * half_extent
    return 1 - falloff.clamp(0, 1)


def _weighted_mean(values: torch.Tensor, weights: Optional[torch.Tensor]) -> torch.Tensor:
    """Mean of ``(..., 1, H, W)`` over its last three dimensions, weighted by ``(H, W)`` weights (``None``: equal)."""
    if weights is None:
        return values.mean(dim=(-3, -2, -1))
    return (values * weights).sum(dim=(-3, -2, -1)) / weights.sum()


def _per_row(value):
    """A number as it is; a 0-d or per-sample ``(B, 1, 1, 1)`` tensor as ``(1 or B, 1)``."""
    return value.reshape(-1, 1) if isinstance(value, torch.Tensor) else value


@device_cached
def _column_offsets(width: int, tables: int, device: torch.device) -> torch.Tensor:
    """``(1, 1, width)``: the first bin of each image column's table, column ``c`` counted into table ``c mod tables``."""
    return (torch.arange(width, device=device) % tables * HISTOGRAM_BINS).reshape(1, 1, width)


def _counted(bins: torch.Tensor, width: int, *amounts: torch.Tensor) -> tuple:
    """``(B, HISTOGRAM_BINS)`` for each of ``amounts`` (``(B, N)``): its sum in each of ``bins`` (``(B, N)``, of images
    ``width`` wide), neighbouring columns counted into different tables (:data:`HISTOGRAM_TABLES`), summed after."""
    batch, tables = bins.shape[0], HISTOGRAM_TABLES
    bins = (bins.reshape(batch, -1, width) + _column_offsets(width, tables, bins.device)).reshape(batch, -1)
    empty = torch.zeros(batch, tables * HISTOGRAM_BINS, dtype=amounts[0].dtype, device=amounts[0].device)
    counted = (empty.scatter_add(1, bins, amount) for amount in amounts)
    return tuple(c.reshape(batch, tables, HISTOGRAM_BINS).sum(dim=1) for c in counted)


def block_stops(stops: torch.Tensor, low, high, block: int) -> tuple:
    """``stops`` (``(B, 1, H, W)``) clamped to ``[low, high]`` and averaged over squares of ``block`` pixels a side:
    ``(means, shares)``, the means ``(B, 1, ceil(H / block), ceil(W / block))`` and each block's share of a whole
    block's pixels ``(ceil(H / block), ceil(W / block))`` (below 1 only for the blocks cut by the frame's right and
    bottom edges, whose means are of their own pixels); at ``block == 1``, ``stops`` as they are and ``None`` (the band
    average clamps the values it counts). Weighted by their shares, the means average to the frame's mean: every pixel
    counts once.

    Examples:
        >>> means, shares = block_stops(torch.arange(6.0).expand(1, 1, 4, 6), -8.0, 8.0, 4)  # four rows of 0 .. 5
        >>> means.flatten().tolist(), shares.flatten().tolist()  # the second block holds two pixels
        ([1.5, 4.5], [1.0, 0.5])
    """
    if block == 1:
        return stops, None
    means = F.avg_pool2d(_clamped(stops, low, high), block, ceil_mode=True)
    return means, _block_shares(stops.shape[-2:], means.shape[-2:], block, stops.dtype, stops.device)


@device_cached
def _block_shares(sides, blocks, block: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """The share of a whole block's ``block²`` pixels that each of the ``blocks`` (rows, columns) of a frame of ``sides``
    holds (:func:`block_stops`)."""
    rows, columns = ((side - block * torch.arange(count, dtype=dtype, device=device)).clamp(max=block) / block
                     for side, count in zip(sides, blocks))
    return rows[:, None] * columns


def _clamped(values: torch.Tensor, low, high) -> torch.Tensor:
    """``values`` clamped to ``[low, high]``: numbers, or tensors that broadcast against ``values``."""
    # torch.clamp takes two numbers or two tensors: a tensor limit with a number beside it takes two passes
    if isinstance(low, torch.Tensor) == isinstance(high, torch.Tensor):
        return values.clamp(low, high)
    return values.clamp(min=low).clamp(max=high)


def histogram_band_average(stops: torch.Tensor, weights: Optional[torch.Tensor], low, high, low_percent, high_percent) -> torch.Tensor:
    """Average of the pixels of ``stops`` (``(B, 1, H, W)``) whose rank lies in ``[low_percent, high_percent]`` %, ``(B,)``.

    The Automatic Histogram of HDRP and Unreal and Bevy's ``AutoExposure``: the pixels' values (log2 luminance,
    clamped to ``[low, high]``) are counted, with their mask weights, into :data:`HISTOGRAM_BINS` equal bins over
    ``[low, high]``; with ``share_k`` bin ``k``'s part of the weight and ``[start_k, end_k]`` its span of the
    cumulative share, its fraction inside the band is ``f_k = |[start_k, end_k] ∩ [low%, high%]| / share_k``, and
    the result is ``sum_k f_k S_k / sum_k f_k W_k`` with ``S_k`` and ``W_k`` the weighted sum of the values and the
    weight in bin ``k``. The engines average the bins' positions; the pixels' own values are averaged here, so a
    uniform frame meters its own value exactly and the result is differentiable in the image (not in the band's
    choice of pixels). ``low``, ``high`` and the percents are numbers, 0-d or ``(B, 1, 1, 1)`` tensors.

    Examples:
        >>> stops = torch.tensor([-3.0, -1.0, 0.5, 2.0, 5.0]).reshape(1, 1, 1, 5)
        >>> round(histogram_band_average(stops, None, -8.0, 8.0, 20.0, 80.0).item(), 4)  # the middle three
        0.5
    """
    batch = stops.shape[0]
    low, high, low_percent, high_percent = (_per_row(v) for v in (low, high, low_percent, high_percent))
    values = _clamped(stops.reshape(batch, -1), low, high)
    # values - low >= 0, so the cast's truncation is the floor
    bins = ((values - low) * (HISTOGRAM_BINS / (high - low))).clamp_max_(HISTOGRAM_BINS - 1).long()
    weight = constant(1.0, values).expand_as(values) if weights is None else weights.reshape(1, -1).expand(batch, -1)
    weight_in_bin, values_in_bin = _counted(bins, stops.shape[-1], weight, values if weights is None else values * weight)
    share = weight_in_bin / weight_in_bin.sum(dim=1, keepdim=True)
    end = share.cumsum(dim=1)
    inside = (end.clamp(max=high_percent / 100) - (end - share).clamp(min=low_percent / 100)).clamp_min(0)
    fraction = inside / share.clamp_min(torch.finfo(share.dtype).tiny)  # 0 in an empty bin: nothing of it is inside
    return (fraction * values_in_bin).sum(dim=1) / (fraction * weight_in_bin).sum(dim=1)


def meter_luminance(image: torch.Tensor, metering: str = "log", mask="average", stop_range: tuple[float, float] = HISTOGRAM_RANGE,
                    percents: tuple[float, float] = (40.0, 90.0), middle_grey=0.18, block: int = HISTOGRAM_BLOCK) -> torch.Tensor:
    """Scene luminance of each image of ``(..., 3, H, W)``, shaped ``image.shape[:-3]``.

    The Rec.709 luminance ``L`` (negative values clipped to 0, non-finite pixels sanitized), averaged with the
    weights of ``mask`` (:func:`metering_weights`):

    * ``"mean"``: the arithmetic mean of ``L``;
    * ``"log"``: the log-average ``exp(mean(log(δ + L))) - δ`` (Reinhard et al. 2002, Eq. 1, "the key"), taken
      per pixel before any averaging so that a few very bright pixels barely move it. Unlike Reinhard's form, δ
      is subtracted again, so a uniform frame meters exactly its luminance. The source document's resampling to
      a 64x64 grid (:func:`area_resize`) and 2x2 averaging (:func:`halving_average`) give this same mean;
    * ``"histogram"``: ``middle_grey * 2^s`` with ``s`` the average of the ``percents`` band of the histogram of
      ``log2(L / middle_grey)`` over ``stop_range`` stops (:func:`histogram_band_average`; defaults HDRP's 40-90 %),
      counted a value for each square of ``block`` pixels a side, the mean of its pixels' stops (:func:`block_stops`,
      :data:`HISTOGRAM_BLOCK`; 1 counts every pixel), the mask taken at the blocks.

    Examples:
        >>> [round(v, 4) for v in meter_luminance(torch.full((2, 3, 8, 8), 0.5), 'mean').tolist()]
        [0.5, 0.5]
        >>> round(meter_luminance(torch.full((1, 3, 8, 8), 0.5), 'histogram').item(), 4)
        0.5
    """
    check_image(image)
    check_choice("metering", metering, METERING_MODES)
    scene = sanitize(image)
    if metering != "histogram":
        return meter_sanitized(scene, metering, metering_weights(mask, scene))
    return meter_histogram(scene, mask, *stop_range, *percents, middle_grey, block)


def meter_sanitized(scene: torch.Tensor, metering: str, weights: Optional[torch.Tensor] = None) -> torch.Tensor:
    """:func:`meter_luminance` ``"mean"`` or ``"log"`` of a frame already sanitized (:func:`~torchgrade.base.images.sanitize`),
    unchecked, with :func:`metering_weights` ``weights``: for a caller that sanitizes the frame anyway.

    Examples:
        >>> [round(v, 4) for v in meter_sanitized(torch.full((1, 3, 4, 4), 0.5), 'mean').tolist()]
        [0.5]
    """
    lum = luminance(scene).clamp_min(0)
    if metering == "log":
        lum = torch.log(lum + LOG_DELTA)
    average = _weighted_mean(lum, weights)
    if metering == "log":
        average = torch.exp(average) - LOG_DELTA
    return average


def meter_histogram(scene: torch.Tensor, mask, low, high, low_percent, high_percent, middle_grey,
                    block: int = HISTOGRAM_BLOCK) -> torch.Tensor:
    """:func:`meter_luminance` ``"histogram"`` of a sanitized ``(..., 3, H, W)`` frame, shaped ``scene.shape[:-3]``:
    ``middle_grey * 2^s``, ``s`` the :func:`histogram_band_average` of ``log2(L / middle_grey)`` over ``[low, high]``
    stops, counted a value a ``block`` (:func:`block_stops`) weighted by ``mask`` (:func:`metering_weights`) at the
    blocks. ``middle_grey`` is a number, 0-d or ``(B, 1, 1, 1)``.

    Examples:
        >>> round(meter_histogram(torch.full((1, 3, 4, 4), 0.09), "average", -8.0, 8.0, 40.0, 90.0, 0.18).item(), 4)
        0.09
    """
    # clamped to the smallest normal number, not 0: black is -126 stops (clamped to the range), with a finite gradient
    lum = luminance(scene).clamp_min(torch.finfo(scene.dtype).tiny).reshape(-1, 1, *scene.shape[-2:])
    stops = torch.log2(lum) - (torch.log2(middle_grey) if isinstance(middle_grey, torch.Tensor) else math.log2(middle_grey))
    means, shares = block_stops(stops, low, high, block)
    weights = metering_weights(mask, means)
    if shares is not None:
        weights = shares if weights is None else weights * shares
    average = histogram_band_average(means, weights, low, high, low_percent, high_percent)
    return (middle_grey * torch.exp2(average.reshape(-1, 1, 1, 1))).reshape(scene.shape[:-3])
