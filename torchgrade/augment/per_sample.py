"""Stages whose choice differs from sample to sample of a batch: the tone mapper each sample drew.

Every mode a sample may draw maps the whole batch, and each sample takes its own mode's result by a select: no value
of the draw is read back (a synchronisation on a GPU, a break in a compiler's graph), so the batch is one graph
whatever its draw, for the cost of one tone mapping a mode.
"""

from __future__ import annotations

import torch

from ..tonemap import tonemap

__all__ = ["tonemap_per_sample"]


def tonemap_per_sample(images: torch.Tensor, choice: torch.Tensor, modes: tuple) -> torch.Tensor:
    """Tone map sample ``i`` of ``images`` with ``modes[choice[i]]``: every mode on every sample, then a select.

    Examples:
        >>> images = torch.full((2, 3, 1, 1), 4.0)
        >>> out = tonemap_per_sample(images, torch.tensor([1, 0]), ("none", "reinhard"))
        >>> out.flatten().tolist()
        [0.800000011920929, 0.800000011920929, 0.800000011920929, 1.0, 1.0, 1.0]
    """
    if len(modes) == 1:
        return tonemap(images, modes[0])
    picked = choice.reshape(-1, 1, 1, 1)
    mapped = [tonemap(images, mode) for mode in modes]
    out = mapped[0]
    for index, candidate in enumerate(mapped[1:], start=1):
        out = torch.where(picked == index, candidate, out)
    return out
