"""Per-pixel modules on strips of rows, as the device's :class:`~torchgrade.runtime.ExecutionPolicy` asks: a module
declares that each of its output pixels depends on its input pixel alone (:func:`pixelwise`), and the runtime decides
how its frames run.

Examples:
    >>> import torch
    >>> image = torch.rand(1, 3, 300, 1000)
    >>> torch.equal(in_strips(torch.sqrt, image), torch.sqrt(image))
    True
"""

from __future__ import annotations

import contextlib
import functools

import torch

from .policy import policy_for

__all__ = ["pixelwise", "in_strips", "named_as"]


def pixelwise(forward=None, *, planes: bool = False):
    """Decorate the ``forward(self, image, *args, **kwargs)`` of a module each of whose output pixels depends on its
    input pixel alone: called, it runs on strips of rows where the device's policy asks (:func:`in_strips`), whole
    when the module ``is_identity`` (it hands its input back). With ``planes``, ``forward`` takes ``planes=True``
    while a compiler traces it: computed on the image's three planes, its chain of steps is one loop (Inductor fuses
    steps over the same number of elements, and a step over a frame's 3 values a pixel after one over a plane's 1
    starts another loop); eager, a step on planes would be three operations instead of one.

    Examples:
        >>> class Square(torch.nn.Module):
        ...     @pixelwise
        ...     def forward(self, image):
        ...         return image * image
        >>> Square()(torch.full((1, 3, 2, 2), 3.0)).flatten().tolist()[:2]
        [9.0, 9.0]
    """

    def decorate(forward):
        @functools.wraps(forward)
        def run(module, image: torch.Tensor, *args, **kwargs):
            if planes and torch.compiler.is_compiling():
                return forward(module, image, *args, planes=True, **kwargs)
            if getattr(module, "is_identity", False):
                return forward(module, image, *args, **kwargs)
            return in_strips(lambda part: forward(module, part, *args, **kwargs), image)

        return run

    return decorate if forward is None else decorate(forward)


def in_strips(transform, image: torch.Tensor) -> torch.Tensor:
    """``transform(image)`` for a per-pixel ``transform``, on strips of rows where the device's policy asks.

    On the CPU an eager per-pixel stage is dozens of whole-tensor operations, each reading and writing the frame from
    memory; on strips of :data:`~torchgrade.runtime.policy.STRIP_PIXELS_PER_THREAD` pixels per thread the intermediates stay
    in cache (``benchmarks/results/cpu_forms.md``, "Strips": the whole frame 1.83 times as long). Strips are joined by
    one concatenation, which autograd and ``torch.func`` transforms record like any other operation. The frame is
    processed whole (the same values) on other devices, when it is not larger than a strip, and while tracing,
    compiling or exporting (the graph takes any size).
    """
    pixels = policy_for(image.device).strip_pixels
    if pixels is None or image.dim() < 3 or image.numel() <= 3 * pixels:
        return transform(image)
    rows = max(1, pixels * image.shape[-2] * image.shape[-3] // image.numel())
    strips = []
    for part in image.split(rows, dim=-2):
        with named_as(part.shape, image.shape):
            strips.append(transform(part))
    return torch.cat(strips, dim=-2)


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
