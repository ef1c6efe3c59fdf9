"""The replica's memory: what it holds now and at its peak, what a request and a batch cost, and the budget requests
reserve from before their bodies are read.

Costs are measured when the replica starts: the growth of its peak resident memory (``VmHWM``, reset through
``/proc/self/clear_refs``) while probe frames of two sizes are decoded, and while they are graded and packed; a line
through the two (:class:`Cost`), times :data:`MARGIN`. A request holds its body twice (the bytes, and the copy a
decoder may take), its decoding's peak and its answer twice (the graded frame and its packed bytes) from the moment
its header is read until it is answered: that much it reserves from the :class:`MemoryBudget`, waiting in line. Its
grading needs more, but only while its batch runs, and one batch runs at a time: the replica keeps a share of the
budget for the running batch and splits a batch whose grading would not fit it.

Free heap pages are handed back to the system before each probe (glibc's ``malloc_trim``), so a probe that reuses them
counts them. Between requests glibc keeps freed memory for reuse; with one malloc arena for the process
(``MALLOC_ARENA_MAX=1``, which ``serve.py`` gives Ray's workers) every thread reuses it, so it adds little to the
peak; the budget leaves :data:`RETAINED_MIB` for what it does add. (Handing every buffer back to the system as it is
freed bounds it too, but then every run faults all its pages in anew, which slowed grading markedly.)
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import ctypes
import resource
import sys
from dataclasses import dataclass

__all__ = ["MARGIN", "RETAINED_MIB", "Cost", "MemoryBudget", "OverBudget", "peak_growth", "peak_mib", "reset_peak",
           "resident_mib"]

MARGIN = 1.25
"""Factor on a measured cost: allocator pages and the small buffers of a run that a probe does not see."""
RETAINED_MIB = 64
"""Freed memory glibc may keep beyond what is reused: twice its largest dynamic mmap threshold (32 MiB on 64-bit
systems), its threshold for handing a free heap top back."""
_MIB = 2**20


def _status_kib(field: str) -> int | None:
    """A ``/proc/self/status`` field in KiB (``VmRSS``: resident now, ``VmHWM``: peak), ``None`` off Linux."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def resident_mib() -> float:
    """This process's resident memory in MiB (off Linux: its peak, from ``getrusage``)."""
    now = _status_kib("VmRSS")
    return now / 1024 if now is not None else peak_mib()


def peak_mib() -> float:
    """This process's peak resident memory in MiB since it started or since :func:`reset_peak`."""
    peak = _status_kib("VmHWM")
    if peak is not None:
        return peak / 1024
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / _MIB if sys.platform == "darwin" else peak / 1024


def reset_peak() -> bool:
    """Reset the peak resident memory to the resident memory now (Linux: ``/proc/self/clear_refs``); False elsewhere."""
    try:
        with open("/proc/self/clear_refs", "w") as clear:
            clear.write("5")
        return True
    except OSError:
        return False


def _release_free_memory() -> None:
    """Hand the heap's free pages back to the system (glibc's ``malloc_trim``); nothing without glibc."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except OSError:
        pass


def peak_growth(run) -> int:
    """Bytes by which ``run()`` raises this process's peak resident memory above its resident memory before."""
    _release_free_memory()
    reset_peak()
    before = resident_mib()
    run()
    return max(0, round((peak_mib() - before) * _MIB))


@dataclass(frozen=True)
class Cost:
    """Bytes a step holds at its peak for a frame of ``pixels`` pixels: ``fixed + per_pixel * pixels``.

    Examples:
        >>> cost = Cost.through((256 * 256, 7 << 20), (512 * 512, 19 << 20), margin=1.0)
        >>> cost.per_pixel, cost.fixed / 2**20, cost.bytes(1000)
        (64.0, 3.0, 3209728)
    """

    fixed: float
    per_pixel: float

    @classmethod
    def through(cls, small: tuple, large: tuple, floor: float = 0.0, margin: float = MARGIN) -> "Cost":
        """The line through two probes ``(pixels, bytes)``, its slope at least ``floor`` bytes a pixel (what the
        frames the step holds take), times ``margin``."""
        (p0, b0), (p1, b1) = small, large
        per_pixel = max((b1 - b0) / (p1 - p0), floor)
        return cls(margin * max(0.0, b1 - per_pixel * p1), margin * per_pixel)

    def bytes(self, pixels: int) -> int:
        return round(self.fixed + self.per_pixel * pixels)

    def pixels(self, room: float) -> int:
        """The most pixels whose cost fits ``room`` bytes."""
        return max(0, int((room - self.fixed) / self.per_pixel)) if self.per_pixel else 1 << 62

    def mib(self) -> dict:
        return {"fixed_mib": round(self.fixed / _MIB, 1), "bytes_per_pixel": round(self.per_pixel, 1)}


class OverBudget(ValueError):
    """A request that could not fit the budget even with the replica idle."""


class MemoryBudget:
    """Bytes requests reserve before their bodies are read, granted first come first served: a request waits while
    the memory is held by others.

    Examples:
        >>> async def two():
        ...     budget = MemoryBudget(100)
        ...     async with budget.reserved(60):
        ...         second = budget.reserved(60)
        ...         waiting = asyncio.ensure_future(second.__aenter__())
        ...         await asyncio.sleep(0)
        ...         held = (budget.held, waiting.done())
        ...     await waiting
        ...     return held, budget.held, budget.waited
        >>> asyncio.run(two())
        ((60, False), 60, 1)
    """

    def __init__(self, capacity: int):
        self.capacity, self.held, self.peak, self.waited = capacity, 0, 0, 0
        self._waiting = collections.deque()

    @contextlib.asynccontextmanager
    async def reserved(self, amount: int):
        """Hold ``amount`` bytes for the ``async with`` block, waiting in line for them; ``OverBudget`` past the
        capacity."""
        if amount > self.capacity:
            raise OverBudget(f"it needs {amount / _MIB:.0f} MiB, more than the {self.capacity / _MIB:.0f} MiB this "
                             "replica's memory budget leaves for requests")
        if self._waiting or self.held + amount > self.capacity:
            await self._wait(amount)
        else:
            self._take(amount)
        try:
            yield
        finally:
            self.held -= amount
            self._grant()

    async def _wait(self, amount: int) -> None:
        granted = asyncio.get_running_loop().create_future()
        self._waiting.append((amount, granted))
        self.waited += 1
        try:
            await granted
        except asyncio.CancelledError:
            if granted.done() and not granted.cancelled():  # granted just as the request was given up
                self.held -= amount
            self._grant()
            raise

    def _take(self, amount: int) -> None:
        self.held += amount
        self.peak = max(self.peak, self.held)

    def _grant(self) -> None:
        while self._waiting and (self._waiting[0][1].done() or self.held + self._waiting[0][0] <= self.capacity):
            amount, granted = self._waiting.popleft()
            if not granted.done():
                self._take(amount)
                granted.set_result(None)

    @property
    def waiting(self) -> int:
        return sum(not granted.done() for _, granted in self._waiting)
