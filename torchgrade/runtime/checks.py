"""Checks of values: range checks of learnable controls on a GPU, without waiting for it, and none in a recorded graph.

A recorded graph (traced, compiled, exported) carries no checks: :class:`DeferredCheck` and :func:`warn_if_eight_bit`
do nothing while one is recorded, so no stage asks.

A learnable control is checked against its range before every forward (an optimiser may have moved it out).
On the CPU the check reads the value directly. On CUDA a read would wait for every queued kernel, once per
frame; instead :class:`DeferredCheck` copies the value to pinned host memory without blocking, and checks the copy
at a later forward, once it has landed. Copies are checked in the order they were made, however far the host runs
ahead of the device. A value an optimiser moved out of its range therefore raises at a later forward (usually the
next one), with the same message, and at every forward after that while it stays out; no forward waits for the GPU.

Examples:
    >>> import torch
    >>> seen = []
    >>> check = DeferredCheck()
    >>> check({"gain": torch.tensor(2.0)}, lambda name, value: seen.append((name, value.item())))
    >>> seen  # on the CPU: checked at once
    [('gain', 2.0)]
"""

from __future__ import annotations

import collections
import threading
import warnings
from typing import Callable, NamedTuple, Optional

import torch

from .policy import one_thread, readable
from .recording import is_tracing


__all__ = ["DeferredCheck", "warn_if_eight_bit", "EIGHT_BIT_ROWS", "EIGHT_BIT_LEVELS"]


EIGHT_BIT_ROWS = 8
"""Rows :func:`warn_if_eight_bit` reads at most (at least half as many), evenly spaced, of the colour of the first image
of a batch: whole rows, read in order (values spread over the frame would fetch a cache line each). Its cost against
a copy of the frame: ``benchmarks/results/cpu_forms.md``, "8-bit check of a frame"."""


EIGHT_BIT_LEVELS = 16
"""Different whole numbers from which a sample reads as an 8-bit picture: a photograph's 8 rows hold far more (the
sample pictures of the suite: every one above 60), a synthetic HDR frame of whole-number lamps on black a handful."""


def warn_if_eight_bit(image: torch.Tensor) -> None:
    """Warn when a linear ``image`` looks like 0..255 data: a sample of it holds whole numbers only, at least
    :data:`EIGHT_BIT_LEVELS` different ones, none negative, the largest in (1, 255]. Such floats taken as light come out
    nearly white; an HDR frame holds fractions, and a frame of a few whole levels (a test pattern of lamps of 8 and
    60 on black) is no 8-bit picture. Only where the device's policy reads values (the CPU,
    :func:`~torchgrade.runtime.policy.readable`): on a GPU the read would wait for the device at every frame.

    Examples:
        >>> import warnings
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     warn_if_eight_bit(torch.arange(48.0).reshape(3, 4, 4) * 5)
        >>> "divide by 255" in str(caught[0].message)
        True
    """
    first = image.detach()[(0,) * (image.dim() - 3)][:3]  # colour, without an alpha
    sample = first[:, :: max(1, first.shape[-2] // EIGHT_BIT_ROWS)]
    if sample.numel() < EIGHT_BIT_LEVELS or not readable(image):  # too few values to hold that many levels
        return
    with one_thread():  # tens of thousands of values: a parallel region's barrier would cost more on a loaded machine
        low, high = torch.stack(sample.aminmax()).tolist()  # one read
        eight_bit = (0.0 <= low < high and 1.0 < high <= 255.0 and torch.equal(sample, sample.round())
                     and sample.unique().numel() >= EIGHT_BIT_LEVELS)  # counted only where the rest holds: almost never
    if eight_bit:
        warnings.warn(
            f"the image looks like 0..255 data (whole numbers up to {high:g}), but stages take linear light: divide "
            "by 255, and decode sRGB-encoded pictures (PNG, JPEG) with tg.color.srgb_to_linear or grade them with "
            'RandomPostFX(input_space="srgb")', UserWarning, stacklevel=3)


class _Copy(NamedTuple):
    """A value's copy on its way to the host, and the check its caller asked for once it has landed."""

    name: str
    host: torch.Tensor
    landed: object  # the CUDA event recorded after the copy
    check: Callable[[str, torch.Tensor], None]


def _deferred(device: torch.device) -> bool:
    """True where reading a value would wait for queued kernels: CUDA."""
    return device.type == "cuda"


def _copy_to_host(value: torch.Tensor) -> tuple:
    """A pinned host copy of ``value``, started without waiting, and the CUDA event recorded after it on the stream
    of ``value``'s device (where the copy runs, whichever device is current)."""
    host = torch.empty(value.shape, dtype=value.dtype, pin_memory=True)
    host.copy_(value, non_blocking=True)
    landed = torch.cuda.Event()
    landed.record(torch.cuda.current_stream(value.device))
    return host, landed


class DeferredCheck:
    """Checks ``check(name, value)`` of a stage's learnable values at every call: at once on the CPU, asynchronously on
    CUDA, never on ``meta`` (no values). Callers may share one (a stage's number controls and its kernel): each copy is
    checked with its own caller's ``check``. Safe to call from several threads."""

    def __init__(self):
        self._lock = threading.Lock()
        self._pending: collections.deque = collections.deque()  # _Copy not yet checked, oldest first

    def __call__(self, values: dict, check: Callable[[str, torch.Tensor], None], summary: Optional[Callable] = None) -> None:
        """Check each of ``values`` (by name): ``check(name, summary(value))``.

        ``summary`` (default: the value itself) reduces a large value to what ``check`` needs (a table to its
        extremes), so only that is copied back. Nothing while a graph is recorded.
        """
        if is_tracing():
            return
        with self._lock:
            for name, value in values.items():
                if value.device.type == "meta":
                    continue
                seen = value.detach() if summary is None else summary(value.detach())
                if _deferred(value.device):
                    host, landed = _copy_to_host(seen)
                    self._pending.append(_Copy(name, host, landed, check))
                else:
                    check(name, seen)
            while self._pending and self._pending[0].landed.query():  # a failure raises; later copies wait their turn
                copy = self._pending.popleft()
                copy.check(copy.name, copy.host)
