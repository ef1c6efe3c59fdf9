"""The pixels a look is fitted and measured on: before/after pairs, masks, and a spatially held-out part.

Each picture is cut into square blocks (about :data:`BLOCKS` of them) and a share ``holdout`` of the blocks is held
out: the errors are measured on every pixel of those blocks, which the fit never sees, not on a random subset of the
same neighbourhoods (a neighbour of a fitted pixel is nearly the same colour, so such a subset says little about the
rest of a picture). The fitting pixels are drawn from the other blocks, stratified by colour (:func:`colour_strata`):
each half stop of luminance and each hue sector gives an equal share where it has the pixels, so the few highlights
and saturated colours that decide a 99.9th percentile are fitted as well as the many mid-tones.

Examples:
    >>> import torch
    >>> source = torch.rand(3, 40, 40)
    >>> pairs = sample_pairs([source], [source * 0.5], None, max_pixels=400, holdout=0.25)
    >>> tuple(pairs.train_source.shape), tuple(pairs.test_source.shape)
    ((1, 3, 400, 1), (1, 3, 400, 1))
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import torch

from ..color import luminance

__all__ = ["BLOCKS", "MAX_TEST_PIXELS", "PixelPairs", "sample_pairs", "as_list", "held_out_blocks", "colour_strata",
           "stratified"]

BLOCKS = 64
"""About how many square blocks a picture is cut into for the held-out split (an 8x8 grid on a square picture)."""

MAX_TEST_PIXELS = 1 << 20
"""Held-out pixels the errors are measured on, at most (a uniform draw among them beyond): a forward pass of the look."""


@dataclass
class PixelPairs:
    """Fitting and held-out pixels as ``(1, 3, N, 1)`` float64 images: per-pixel stages see a column of pixels.

    The fitting pixels are in random order, so their first ``n`` are a stratified sample of ``n`` too.
    """

    train_source: torch.Tensor
    train_target: torch.Tensor
    test_source: torch.Tensor
    test_target: torch.Tensor


def as_list(images) -> list | None:
    """One tensor or a sequence of them, as a list (``None`` stays ``None``)."""
    if images is None or isinstance(images, torch.Tensor):
        return images if images is None else [images]
    return list(images)


def _checked(source: torch.Tensor, target: torch.Tensor, index: int) -> None:
    for name, image in (("source", source), ("target", target)):
        if not isinstance(image, torch.Tensor) or image.dim() not in (3, 4) or image.shape[-3] < 3:
            raise ValueError(f"{name} {index} must be a (3, H, W) or (B, 3, H, W) tensor, got {getattr(image, 'shape', type(image).__name__)}")
    if source.shape[-2:] != target.shape[-2:] or source.shape[:-3] != target.shape[:-3]:
        raise ValueError(f"pair {index}: source {tuple(source.shape)} and target {tuple(target.shape)} differ in size")


def held_out_blocks(batch: int, height: int, width: int, holdout: float, generator: Optional[torch.Generator]) -> torch.Tensor:
    """Which pixels of ``batch`` pictures of ``height`` x ``width`` lie in held-out blocks, as ``(batch, height, width)``.

    Blocks are squares of side ``ceil(sqrt(height * width / BLOCKS))``; ``round(holdout * blocks)`` of them, drawn at
    random, are held out, and at least one block is left on each side.

    Examples:
        >>> held = held_out_blocks(1, 8, 8, 0.25, torch.Generator().manual_seed(0))
        >>> held.sum().item(), held.float().reshape(8, 8).mean().item()   # 16 of the 64 one-pixel blocks
        (16, 0.25)
    """
    side = max(1, math.ceil(math.sqrt(height * width / BLOCKS)))
    rows, columns = -(-height // side), -(-width // side)
    count = batch * rows * columns
    if count < 2:
        raise ValueError(f"a {width}x{height} picture is too small to hold pixels out: give at least 2 pixels")
    held = min(count - 1, max(1, round(holdout * count)))
    chosen = torch.zeros(count, dtype=torch.bool)
    chosen[torch.randperm(count, generator=generator)[:held]] = True
    grid = chosen.reshape(batch, rows, columns)
    return grid.repeat_interleave(side, dim=1)[:, :height].repeat_interleave(side, dim=2)[:, :, :width]


def colour_strata(rgb: torch.Tensor) -> torch.Tensor:
    """A stratum for each ``(3, N)`` linear colour: its half stop of luminance, times its hue sector (six, by the
    largest and smallest channel) or grey (chroma under a tenth of the largest channel).

    Examples:
        >>> grey, brighter, red = [0.18, 0.18, 0.18], [0.36, 0.36, 0.36], [0.5, 0.1, 0.1]
        >>> colour_strata(torch.tensor([grey, brighter, red]).T).tolist()   # a stop up: 2 x 7 on; red: grey's + 1
        [301, 315, 302]
    """
    lit = luminance(rgb[..., None])[0, :, 0].clamp(2.0**-24, 2.0**24)
    stop = (2.0 * torch.log2(lit)).floor().long() + 48  # half stops from 2^-24 up: 0..96
    top, bottom = rgb.max(dim=0), rgb.min(dim=0).values
    grey = (top.values - bottom) <= 0.1 * top.values.abs()
    middle = rgb.sum(dim=0) - top.values - bottom
    rising = middle >= (top.values + bottom) / 2  # which neighbour of the largest channel's sector
    sector = torch.where(grey, torch.zeros_like(stop), 1 + 2 * top.indices + rising.long())
    return stop * 7 + sector


def stratified(strata: torch.Tensor, count: int, generator: Optional[torch.Generator]) -> torch.Tensor:
    """Indices of ``count`` of the items (or all of them, when fewer) in random order, drawn evenly over the strata:
    a stratum gives all its items or as many as any other gives, give or take one.

    Examples:
        >>> strata = torch.tensor([0] * 90 + [1] * 8 + [2] * 2)
        >>> chosen = stratified(strata, 20, torch.Generator().manual_seed(0))
        >>> torch.bincount(strata[chosen]).tolist()   # both of stratum 2, all 8 of stratum 1, 10 of the 90
        [10, 8, 2]
    """
    order = torch.randperm(len(strata), generator=generator)
    ranked, position = torch.sort(strata[order], stable=True)
    counts = torch.bincount(ranked)
    first = counts.cumsum(0) - counts
    rank = torch.arange(len(ranked)) - first[ranked]  # a random rank within each stratum
    share = _equal_share(counts, count)
    whole = torch.nonzero(rank < share - 1).flatten()
    edge = torch.nonzero(rank == share - 1).flatten()  # the last item of each stratum that has it: some are left
    edge = edge[torch.randperm(len(edge), generator=generator)[: max(0, count - len(whole))]]
    chosen = order[position[torch.cat((whole, edge))]]
    return chosen[torch.randperm(len(chosen), generator=generator)]


def _equal_share(counts: torch.Tensor, count: int) -> int:
    """The smallest share ``s`` such that ``sum(min(counts, s)) >= count`` (the largest count when they fall short)."""
    levels = torch.sort(counts).values
    below = levels.cumsum(0) - levels  # the items of the strata smaller than each level
    reached = below + levels * torch.arange(len(levels), 0, -1)  # taken with a share of that level
    over = torch.nonzero(reached >= count)
    if len(over) == 0:
        return int(levels[-1])
    index = int(over[0])
    return math.ceil((count - float(below[index])) / (len(levels) - index))


def _columns(image: torch.Tensor) -> torch.Tensor:
    return image[..., :3, :, :].double().movedim(-3, 0).reshape(3, -1)


def sample_pairs(sources, targets, masks, max_pixels: int = 16384, holdout: float = 0.25,
                 generator: Optional[torch.Generator] = None, max_test_pixels: int = MAX_TEST_PIXELS) -> PixelPairs:
    """Hold out ``holdout`` of each picture's blocks (:func:`held_out_blocks`) and draw ``max_pixels`` fitting pixels
    from the others (:func:`stratified` by :func:`colour_strata`); the held-out pixels are all those of the held-out
    blocks (at most ``max_test_pixels``, drawn uniformly). Pixels outside a mask or with a non-finite target are left out.
    """
    sources, targets, masks = as_list(sources), as_list(targets), as_list(masks)
    if len(sources) != len(targets) or (masks is not None and len(masks) != len(sources)):
        raise ValueError(f"give as many targets (and masks) as sources, got {len(sources)} and {len(targets)}")
    if not 0.0 < holdout < 1.0:
        raise ValueError(f"holdout must lie in (0, 1), got {holdout}")
    parts: dict[str, list[torch.Tensor]] = {"source": [], "target": [], "held": []}
    for index, (source, target) in enumerate(zip(sources, targets)):
        _checked(source, target, index)
        batch = source.shape[0] if source.dim() == 4 else 1
        height, width = source.shape[-2:]
        held = held_out_blocks(batch, height, width, holdout, generator).to(source.device).reshape(-1)
        source_columns, target_columns = _columns(source), _columns(target)
        keep = torch.isfinite(target_columns).all(dim=0)
        if masks is not None:
            mask = torch.as_tensor(masks[index], device=keep.device)
            if mask.numel() != keep.numel():
                raise ValueError(f"mask {index} has {mask.numel()} values for {keep.numel()} pixels")
            keep &= mask.reshape(-1).bool()
        for name, values in (("source", source_columns), ("target", target_columns), ("held", held)):
            parts[name].append(values[..., keep])
    source, target, held = (torch.cat(parts[name], dim=-1) for name in ("source", "target", "held"))
    if source.shape[1] < 8:
        raise ValueError(f"need at least 8 pixels inside the masks to fit a look, got {source.shape[1]}")
    fitting, tested = torch.nonzero(~held.cpu()).flatten(), torch.nonzero(held.cpu()).flatten()
    if len(fitting) == 0 or len(tested) == 0:
        raise ValueError("every pixel inside the masks lies on one side of the held-out split: give a larger mask")
    train = fitting[stratified(colour_strata(source[:, fitting].cpu()), max_pixels, generator)]
    test = tested[torch.randperm(len(tested), generator=generator)[:max_test_pixels]]

    def column(pixels, chosen):
        return pixels[:, chosen.to(pixels.device)].reshape(1, 3, -1, 1)

    return PixelPairs(column(source, train), column(target, train), column(source, test), column(target, test))
