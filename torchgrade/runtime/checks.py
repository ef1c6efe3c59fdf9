"""Checks of values: range checks of learnable controls on a GPU, without waiting for it, and none in a recorded graph.

A recorded graph (traced, compiled, exported) carries no checks: :class:`DeferredCheck` and :func:`check_eagerly` do
nothing while one is recorded, so no stage asks.

A learnable control is checked against its range before every forward (an optimiser may have moved it out).
On the CPU the check reads the value directly. On CUDA a read would wait for every queued kernel, once per
frame; instead :class:`DeferredCheck` copies a value to pinned host memory without blocking when its version
changes (an optimiser step changes it in place), and checks the copy at a later forward, once the copy has
landed. Copies are checked in order, however far the host runs ahead of the device. A value an optimiser moved
out of its range therefore raises at a later forward (usually the next one), with the same message, and at every
forward after that while it stays unchanged; no forward waits for the GPU.

A copy that fails after its value has changed again (a later step may have brought it back) raises only if the
copy before it or the next one fails too: a value restored before its bad copy landed raises nothing.

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

    value: torch.Tensor
    version: int  # the value's version when copied
    host: torch.Tensor
    landed: object  # the CUDA event recorded after the copy
    check: Callable[[str, torch.Tensor], None]

    def describes(self, value: torch.Tensor) -> bool:
        """True when this copy was made from ``value`` as it is now."""
        return self.value is value and self.version == value._version


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
    """Checks ``check(name, value)`` of a stage's learnable values: at once on the CPU, asynchronously on CUDA,
    once per change of a value (its tensor version), never on ``meta`` (no values). Callers may share one
    (a stage's number controls and its kernel): each copy is checked with its own caller's ``check``.
    Safe to call from several threads."""

    def __init__(self):
        self._lock = threading.Lock()
        self._passed: dict = {}  # name -> (tensor, version) whose check passed
        self._failed: dict = {}  # name -> the _Copy whose check raised last
        self._pending: dict = {}  # name -> deque of _Copy not yet checked, oldest first
        self._failing: set = set()  # names whose last landed copy failed

    def __call__(self, values: dict, check: Callable[[str, torch.Tensor], None], summary: Optional[Callable] = None) -> None:
        """Check each of ``values`` (by name) whose tensor or version changed: ``check(name, summary(value))``.

        ``summary`` (default: the value itself) reduces a large value to what ``check`` needs (a table to its
        extremes), so only that is copied back. Nothing while a graph is recorded.
        """
        if is_tracing():
            return
        with self._lock:
            for name, value in values.items():
                passed = self._passed.get(name)
                if value.device.type == "meta" or (passed is not None and passed[0] is value and passed[1] == value._version):
                    continue
                failed = self._failed.get(name)
                if failed is not None and failed.describes(value):
                    failed.check(name, failed.host)  # raises again, as the CPU does at every forward
                if not _deferred(value.device):
                    check(name, value.detach() if summary is None else summary(value.detach()))
                    self._passed[name] = (value, value._version)
                    continue
                queue = self._pending.setdefault(name, collections.deque())
                if not queue or not queue[-1].describes(value):
                    summarised = value.detach() if summary is None else summary(value.detach())
                    queue.append(_Copy(value, value._version, *_copy_to_host(summarised), check))
            self._check_landed()

    def _check_landed(self) -> None:
        """Check every copy that has landed, oldest first; raise the first failure that counts."""
        for name, queue in self._pending.items():
            while queue and queue[0].landed.query():
                self._judge(name, queue.popleft())

    def _judge(self, name: str, copy: _Copy) -> None:
        try:
            copy.check(name, copy.host)
        except ValueError:
            repeated = name in self._failing
            self._failing.add(name)
            if copy.value._version == copy.version or repeated:  # unchanged since, or not back in range since
                self._failed[name] = copy
                self._pending[name].clear()  # copies made before this report: the value is copied again as it is now
                raise
        else:
            self._failing.discard(name)
            self._passed[name] = (copy.value, copy.version)
