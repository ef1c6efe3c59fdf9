"""Per-pixel stages on strips of rows, as the device's :class:`~torchgrade.runtime.ExecutionPolicy` asks.

Examples:
    >>> import torch
    >>> image = torch.rand(1, 3, 300, 1000)
    >>> torch.equal(in_strips(torch.sqrt, image), torch.sqrt(image))
    True
"""

from __future__ import annotations

import contextlib

import torch

from .recording import untracked
from .policy import policy_for

__all__ = ["in_strips", "named_as"]


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
        part = image[..., start : start + rows, :]
        with named_as(part.shape, image.shape):
            strip = transform(part)
        if output is None:
            output = strip.new_empty(strip.shape[:-2] + (height, strip.shape[-1]))
        output[..., start : start + rows, :] = strip
    return output


@contextlib.contextmanager
def named_as(part: torch.Size, whole: torch.Size):
    """A ``ValueError`` or ``TypeError`` raised in the block that names the shape ``part`` (of a strip, or of an image's
    colour channels) is raised naming ``whole``, the shape the caller passed.

    Examples:
        >>> with named_as(torch.Size((1, 3, 8, 10)), torch.Size((1, 3, 80, 10))):
        ...     raise ValueError("got (1, 3, 8, 10)")
        Traceback (most recent call last):
        ...
        ValueError: got (1, 3, 80, 10)
    """
    try:
        yield
    except (ValueError, TypeError) as error:
        seen, caller = str(tuple(part)), str(tuple(whole))
        if type(error) not in (ValueError, TypeError) or seen == caller or seen not in str(error):
            raise
        raise type(error)(str(error).replace(seen, caller)).with_traceback(error.__traceback__) from None
