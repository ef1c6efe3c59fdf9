"""Untrusted files opened safely: regular files only, their size bounded before a byte is read.

Opening a FIFO waits for a writer (for ever, when none comes), a character device such as ``/dev/zero`` never ends,
and neither has a size to check beforehand. :func:`open_regular` refuses both before opening (``os.stat``), opens
without blocking and checks the descriptor again (the path may have changed in between), and checks the size against
the caller's budget; :func:`read_regular` reads the whole file within that budget.

A size says nothing of some files: the kernel's (``/proc/self/mem``, ``/proc/self/status``) are regular files of size
0 whatever they hold, and a file may grow while it is read. So a file of size 0 is refused before it is read (no
format read here has an empty file), and the handle itself reads no further than the budget: a byte past it is
refused as it arrives.

Examples:
    >>> read_regular("/dev/zero", 10, "LUT")
    Traceback (most recent call last):
    ...
    ValueError: LUT /dev/zero is not a regular file
    >>> read_regular("/proc/self/mem", 10, "LUT")
    Traceback (most recent call last):
    ...
    ValueError: LUT /proc/self/mem is empty (0 bytes: a kernel file, as /proc's, says 0 whatever it holds)
"""

from __future__ import annotations

import io
import os
import stat
from typing import TYPE_CHECKING, BinaryIO

if TYPE_CHECKING:
    from _typeshed import MaybeNone  # None where a non-blocking read finds no data, as io.FileIO.read's stub states

__all__ = ["check_regular", "open_regular", "read_regular"]


def check_regular(path, what: str) -> None:
    """``FileNotFoundError`` where ``path`` names nothing, ``ValueError`` where it names no regular file (a pipe, a
    device, a folder), for a reader that opens the file itself (a library's, by its path).

    Examples:
        >>> check_regular("/dev/null", "EXR file")
        Traceback (most recent call last):
        ...
        ValueError: EXR file /dev/null is not a regular file
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"no such {what}: {path}") from None
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"{what} {path} is not a regular file")


def open_regular(path, max_bytes: int, what: str) -> BinaryIO:
    """``path`` opened for binary reading, if it is a regular file of at most ``max_bytes`` bytes; ``ValueError``
    naming ``what`` it was to be otherwise (``FileNotFoundError`` where there is no file)."""
    _check(os.stat(path), path, max_bytes, what)
    descriptor = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    try:
        raw = _Bounded(descriptor, max_bytes, f"{what} {path} is larger than {max_bytes} bytes (it grew as it was read)")
    except BaseException:
        os.close(descriptor)
        raise
    handle = io.BufferedReader(raw)
    try:
        _check(os.fstat(handle.fileno()), path, max_bytes, what)
        if hasattr(os, "set_blocking"):
            os.set_blocking(handle.fileno(), True)
    except BaseException:
        handle.close()
        raise
    return handle


def read_regular(path, max_bytes: int, what: str) -> bytes:
    """The bytes of ``path``, a regular file of at most ``max_bytes`` bytes (:func:`open_regular`); a file that grew
    past the budget while it was read is refused too."""
    with open_regular(path, max_bytes, what) as handle:
        return handle.read()


class _Bounded(io.FileIO):
    """A file read no further than ``limit`` bytes from its start, and one more to tell: that byte raises
    ``ValueError(message)``."""

    def __init__(self, descriptor: int, limit: int, message: str):
        super().__init__(descriptor, "r")
        self._limit, self._message = limit, message

    def readinto(self, buffer) -> int | None:
        room = self._limit + 1 - self.tell()
        count = super().readinto(memoryview(buffer).cast("B")[:max(room, 1)])
        if count and self.tell() > self._limit:
            raise ValueError(self._message)
        return count

    def readall(self) -> bytes:
        chunks = []
        while chunk := self.read(io.DEFAULT_BUFFER_SIZE):
            chunks.append(chunk)
        return b"".join(chunks)

    def read(self, size: int | None = -1) -> bytes | MaybeNone:
        if size is None or size < 0:
            return self.readall()
        buffer = bytearray(size)
        count = self.readinto(buffer)
        return None if count is None else bytes(buffer[:count])


def _check(info: os.stat_result, path, max_bytes: int, what: str) -> None:
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"{what} {path} is not a regular file")
    if info.st_size == 0:
        raise ValueError(f"{what} {path} is empty (0 bytes: a kernel file, as /proc's, says 0 whatever it holds)")
    if info.st_size > max_bytes:
        raise ValueError(f"{what} {path} is larger than {max_bytes} bytes ({info.st_size})")
