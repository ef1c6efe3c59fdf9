"""The pixels a look is fitted and measured on: before/after pairs, masks, a held-out split.

Examples:
    >>> import torch
    >>> source = torch.rand(3, 10, 10)
    >>> pairs = sample_pairs([source], [source * 0.5], None, max_pixels=40, holdout=0.25)
    >>> tuple(pairs.train_source.shape), tuple(pairs.test_source.shape)
    ((1, 3, 40, 1), (1, 3, 25, 1))
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import torch

__all__ = ["PixelPairs", "sample_pairs", "as_list"]


@dataclass
class PixelPairs:
    """Fitting and held-out pixels as ``(1, 3, N, 1)`` float64 images: per-pixel stages see a column of pixels."""

    train_source: torch.Tensor
    train_target: torch.Tensor
    test_source: torch.Tensor
    test_target: torch.Tensor


def as_list(images) -> list | None:
    """One tensor or a sequence of them, as a list (``None`` stays ``None``)."""
    if images is None or isinstance(images, torch.Tensor):
        return images if images is None else [images]
    return list(images)


def _columns(source: torch.Tensor, target: torch.Tensor, mask, index: int) -> tuple:
    """A pair as ``(3, P)`` columns of the pixels that count (inside the mask, finite target)."""
    for name, image in (("source", source), ("target", target)):
        if not isinstance(image, torch.Tensor) or image.dim() not in (3, 4) or image.shape[-3] < 3:
            raise ValueError(f"{name} {index} must be a (3, H, W) or (B, 3, H, W) tensor, got {getattr(image, 'shape', type(image).__name__)}")
    if source.shape[-2:] != target.shape[-2:] or source.shape[:-3] != target.shape[:-3]:
        raise ValueError(f"pair {index}: source {tuple(source.shape)} and target {tuple(target.shape)} differ in size")
    source, target = (t[..., :3, :, :].double().movedim(-3, 0).reshape(3, -1) for t in (source, target))
    keep = torch.isfinite(target).all(dim=0)
    if mask is not None:
        mask = torch.as_tensor(mask, device=keep.device)
        if mask.numel() != keep.numel():
            raise ValueError(f"mask {index} has {mask.numel()} values for {keep.numel()} pixels")
        keep &= mask.reshape(-1).bool()
    return source[:, keep], target[:, keep]


def sample_pairs(sources, targets, masks, max_pixels: int = 16384, holdout: float = 0.25,
                 generator: Optional[torch.Generator] = None) -> PixelPairs:
    """Pool the pairs' pixels, shuffle, hold out ``holdout`` of them, keep at most ``max_pixels`` of each part."""
    sources, targets, masks = as_list(sources), as_list(targets), as_list(masks)
    if len(sources) != len(targets) or (masks is not None and len(masks) != len(sources)):
        raise ValueError(f"give as many targets (and masks) as sources, got {len(sources)} and {len(targets)}")
    if not 0.0 < holdout < 1.0:
        raise ValueError(f"holdout must lie in (0, 1), got {holdout}")
    columns = [_columns(s, t, None if masks is None else masks[i], i) for i, (s, t) in enumerate(zip(sources, targets))]
    source = torch.cat([c[0] for c in columns], dim=1)
    target = torch.cat([c[1] for c in columns], dim=1)
    if source.shape[1] < 8:
        raise ValueError(f"need at least 8 pixels inside the masks to fit a look, got {source.shape[1]}")
    order = torch.randperm(source.shape[1], generator=generator)
    held = max(1, int(round(holdout * len(order))))
    test, train = order[:held][:max_pixels], order[held:][:max_pixels]

    def column(pixels, chosen):
        return pixels[:, chosen].reshape(1, 3, -1, 1)

    return PixelPairs(column(source, train), column(target, train), column(source, test), column(target, test))
