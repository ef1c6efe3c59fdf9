"""Per-pixel stages on strips of rows, as the device's :class:`~torchgrade.runtime.ExecutionPolicy` asks.

Examples:
    >>> import torch
    >>> image = torch.rand(1, 3, 300, 1000)
    >>> torch.equal(in_strips(torch.sqrt, image), torch.sqrt(image))
    True
"""

from __future__ import annotations

import torch

from .recording import untracked
from .policy import policy_for

__all__ = ["in_strips"]


def in_strips(transform, image: torch.Tensor, controls=()) -> torch.Tensor:
    """``transform(image)`` for a per-pixel ``transform``, on strips of rows where the device's policy asks.

    On the CPU an eager per-pixel stage is dozens of whole-tensor operations, each reading and writing the
    frame from memory; on strips of :data:`~torchgrade.runtime.STRIP_PIXELS_PER_THREAD` pixels per thread the
    intermediates stay in cache and each result is copied into the output while hot. The frame is processed whole (the same values) on other devices, when it is not
    larger than a strip, while tracing, compiling or exporting (the graph takes any size), and when autograd
    records the call (``image`` or a tensor of ``controls`` requires grad), which would keep every strip's
    intermediates.
    """
    policy = policy_for(image.device)
    pixels = policy.strip_pixels
    if pixels is None or image.dim() < 3 or image.numel() <= 3 * pixels or not untracked(image, *controls):
        return transform(image)
    height = image.shape[-2]
    rows = max(1, pixels * height * image.shape[-3] // image.numel())
    output = None
    for start in range(0, height, rows):
        strip = transform(image[..., start : start + rows, :])
        if output is None:
            output = strip.new_empty(strip.shape[:-2] + (height, strip.shape[-1]))
        output[..., start : start + rows, :] = strip
    return output
