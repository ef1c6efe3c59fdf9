"""A request's body as the replica reads it: no slower than a minimum rate, never past its declared length, held in
one buffer allocated only once the request's memory is granted.

Ray Serve's proxy (uvicorn) bounds a request only end to end (``request_timeout_s``), and the replica's request slot
is held while the body arrives: a client sending a frame at a byte a second keeps a slot for the whole timeout. So a
body must keep pace here: ``t`` seconds after the replica took the request, at least ``rate * (t - grace_s)`` bytes
must have come, or the request is answered 408 and its slot freed. The rate is ``min_rate``, or where it is faster the
pace that ends the body before the request's deadline (the proxy's timeout): a large body sent slowly would hold its
slot and the memory it reserved until that timeout, and be answered 408 then anyway. Time the replica spends waiting
for the request's memory is not counted (:meth:`Body.pause`): the proxy keeps reading the body meanwhile, but the
replica does not.
"""

from __future__ import annotations

import asyncio
import time

__all__ = ["Body", "Refused"]


class Refused(Exception):
    """A request answered with a 4xx status and a reason."""

    def __init__(self, status: int, reason: str):
        super().__init__(reason)
        self.status = status


class Body:
    """The body of ``request``, ``length`` bytes by its ``Content-Length``, read at ``min_rate`` bytes a second or
    faster after ``grace_s`` seconds, and fast enough to end by ``deadline`` (``time.monotonic()``; ``Refused(408)``
    otherwise): first a head of it (:meth:`head`), then the whole (:meth:`whole`)."""

    def __init__(self, request, length: int, min_rate: float, grace_s: float, deadline: float):
        self.length, self.min_rate, self.grace_s, self.deadline = length, min_rate, grace_s, deadline
        self._chunks = request.stream().__aiter__()
        self._started = time.monotonic()
        self._head = bytearray()
        self.size, self.ended = 0, length == 0

    def _rate(self) -> float:
        """Bytes a second the body must keep up with after the grace: ``min_rate``, or the pace that ends it by the
        deadline where that is faster."""
        window = self.deadline - self._started - self.grace_s
        return max(self.min_rate, self.length / window) if window > 0 else float("inf")

    async def _next(self) -> bytes:
        """The next chunk (``b""`` at the end), refused if it comes after the rate's line."""
        rate = self._rate()
        due = self._started + self.grace_s + self.size / rate - time.monotonic()
        try:
            chunk = await asyncio.wait_for(self._chunks.__anext__(), max(due, 0.0))
        except asyncio.TimeoutError:
            raise Refused(408, f"the body came slower than {rate:.0f} bytes a second ({self.size} of "
                               f"{self.length} bytes after {time.monotonic() - self._started:.1f} s)") from None
        except StopAsyncIteration:
            chunk = b""
        self.size += len(chunk)
        if self.size > self.length:
            raise Refused(413, f"the body is longer than the {self.length} bytes its Content-Length declares")
        self.ended = self.ended or not chunk or self.size == self.length
        return chunk

    def pause(self, seconds: float) -> None:
        """Leave ``seconds`` the replica did not read out of the body's time."""
        self._started += seconds

    async def head(self, size: int) -> bytes:
        """The body's first ``size`` bytes at least (the whole body where it is shorter)."""
        while len(self._head) < size and not self.ended:
            self._head += await self._next()
        return bytes(self._head)

    async def whole(self) -> bytearray:
        """Every byte of the body, in a buffer of its declared length; ``ValueError`` where it ends short."""
        buffer, at = bytearray(self.length), len(self._head)
        buffer[:at] = self._head
        self._head = bytearray()
        while not self.ended:
            chunk = await self._next()
            buffer[at:at + len(chunk)] = chunk
            at += len(chunk)
        if at != self.length:
            raise ValueError(f"the body ended after {at} of the {self.length} bytes its Content-Length declares")
        return buffer
