"""Where a frame is computed, and how: the execution policy of each device, decided here and nowhere else.

The maths modules write each formula once; how its operations run depends on the device, not on the maths:

* **CPU**: a per-pixel module runs on strips of rows of :data:`STRIP_PIXELS_PER_THREAD` pixels per intra-op thread
  (:func:`~torchgrade.runtime.strips.pixelwise`), so that each thread's share of a strip's intermediates stays in its
  core's cache while every operation uses all the threads. A value of the data may be read back (free on the CPU):
  checks of values run there (:mod:`torchgrade.runtime.checks`).
* **Any other device** (CUDA, ``meta``, ...): whole frames. Each operation is a kernel launch there, and a strip
  loop multiplies launches for no cache to gain (``benchmarks/results/gpu.md``, the stages' "before (strips / none)");
  a value read back is a synchronisation, so no check reads one at once.
* **While tracing, compiling or exporting**: one graph of whole frames, no reads.

Examples:
    >>> import torch
    >>> policy_for(torch.device("meta")).strip_pixels is None
    True
    >>> policy_for(torch.device("cpu")).strip_pixels == STRIP_PIXELS_PER_THREAD * torch.get_num_threads()
    True
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Optional

import torch

from .recording import is_tracing

__all__ = ["ExecutionPolicy", "policy_for", "readable", "STRIP_PIXELS_PER_THREAD", "one_thread"]

STRIP_PIXELS_PER_THREAD = 1 << 16
"""Pixels of a CPU strip per intra-op thread (batch included): a strip's intermediates stay in the cores' caches,
and each of its dozens of operations is dispatched by Python once a strip, so smaller strips pay that more often and
much larger ones leave the cache; twice this size runs about as fast on 2 cores (grade and tone map of
``export/looks/cinematic.json`` at 1920x1080 in strips of 2^15 to 2^19 pixels a thread and whole:
``benchmarks/results/cpu_forms.md``, "Strips"). A strip grows with the thread count: each thread's share stays that
size, and a frame on many cores is fewer strips."""

@dataclass(frozen=True)
class ExecutionPolicy:
    """How a device computes a frame.

    Attributes:
        strip_pixels: pixels per strip of a per-pixel module, or ``None`` for whole frames.
        reads_values: a value of the data may be read back (a check of it): free on the CPU, a synchronisation of the
            device elsewhere.
    """

    strip_pixels: Optional[int]
    reads_values: bool


WHOLE_FRAMES = ExecutionPolicy(strip_pixels=None, reads_values=False)
"""Off the CPU, and while tracing, compiling or exporting."""


def policy_for(device: torch.device) -> ExecutionPolicy:
    """The execution policy of ``device``, for the calling thread (its intra-op thread count).

    Examples:
        >>> import torch
        >>> policy_for(torch.device("cuda", 0)) == WHOLE_FRAMES
        True
    """
    if device.type != "cpu" or is_tracing():
        return WHOLE_FRAMES
    threads = torch.get_num_threads()
    return ExecutionPolicy(strip_pixels=STRIP_PIXELS_PER_THREAD * threads, reads_values=True)


def readable(value) -> bool:
    """Whether ``value`` can be checked in a forward pass without waiting for a device: a plain value, or a tensor
    where the device's policy reads values (the CPU), outside tracing.

    Examples:
        >>> readable(0.5), readable(torch.tensor(0.5)), readable(torch.tensor(0.5, device="meta"))
        (True, True, False)
    """
    if not isinstance(value, torch.Tensor):
        return True
    return not is_tracing() and policy_for(value.device).reads_values


@contextlib.contextmanager
def one_thread():
    """Run the block with one intra-op CPU thread, then restore the count (thread-local under OpenMP and MKL).

    Examples:
        >>> import torch
        >>> before = torch.get_num_threads()
        >>> with one_thread():
        ...     torch.get_num_threads()
        1
        >>> torch.get_num_threads() == before
        True
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
