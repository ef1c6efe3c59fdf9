"""Stages whose choice differs from sample to sample of a batch: the tone mapper each sample drew.

Each mode is evaluated once, on the samples that chose it (the batch is sorted by mode, split, mapped and put back in
order), so a batch costs one tone mapper per sample whatever the number of modes; counting the modes reads one small
tensor back from the device, which a GPU (and a graph) does without: there every mode maps every sample.
"""

from __future__ import annotations

import torch

from ..runtime.policy import readable
from ..tonemap import tonemap

__all__ = ["tonemap_per_sample"]


def tonemap_per_sample(images: torch.Tensor, choice: torch.Tensor, modes: tuple) -> torch.Tensor:
    """Tone map sample ``i`` of ``images`` with ``modes[choice[i]]``: on the CPU each mode evaluated once on its
    samples; where reading the draw back would wait for the device (and while tracing), every mode on every sample.

    Examples:
        >>> images = torch.full((2, 3, 1, 1), 4.0)
        >>> out = tonemap_per_sample(images, torch.tensor([1, 0]), ("none", "reinhard"))
        >>> out.flatten().tolist()
        [0.800000011920929, 0.800000011920929, 0.800000011920929, 1.0, 1.0, 1.0]
    """
    if len(modes) == 1:
        return tonemap(images, modes[0])
    if not readable(images):
        # Without reading the draw back (a synchronisation off the CPU): every mode on every sample, then a select.
        picked = choice.reshape(-1, 1, 1, 1)
        mapped = [tonemap(images, mode) for mode in modes]
        out = mapped[0]
        for index, candidate in enumerate(mapped[1:], start=1):
            out = torch.where(picked == index, candidate, out)
        return out
    order = torch.argsort(choice, stable=True)
    counts = torch.bincount(choice, minlength=len(modes)).tolist()
    groups = images.index_select(0, order).split(counts)
    mapped = torch.cat([tonemap(group, mode) for group, mode in zip(groups, modes) if len(group)])
    return mapped.index_select(0, torch.argsort(order))
