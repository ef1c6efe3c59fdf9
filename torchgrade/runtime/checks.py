"""Checks of values: range checks of learnable controls on a GPU, without waiting for it, and none in a recorded graph.

A recorded graph (traced, compiled, exported) carries no checks: :class:`DeferredCheck` and :func:`check_eagerly` do
nothing while one is recorded, so no stage asks.

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
from typing import Callable, NamedTuple, Optional

import torch

from .recording import is_tracing

__all__ = ["DeferredCheck", "check_eagerly"]


def check_eagerly(check: Callable, *args, **kwargs) -> None:
    """``check(*args, **kwargs)``, except while a graph is recorded (it carries no checks; a check of a tensor's value
    would break a compiler's graph).

    Examples:
        >>> check_eagerly(lambda x: print("checked", x), 3)
        checked 3
    """
    if not is_tracing():
        check(*args, **kwargs)


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
                    self._pending.append(_Copy(name, *_copy_to_host(seen), check))
                else:
                    check(name, seen)
            while self._pending and self._pending[0].landed.query():  # a failure raises; later copies wait their turn
                copy = self._pending.popleft()
                copy.check(copy.name, copy.host)
