"""What the serving example's server and client share: the raw frame format (image files: ``images.py``).

**Frame format** (little-endian): a 16-byte header, ``b"TGF1"``, ``uint32`` height, ``uint32`` width, the numpy
dtype string of the samples (``"|u1"``, ``"<u2"``, ``"<f2"``, ``"<f4"``) NUL-padded to 4 bytes; then
``height * width * 3`` samples, RGB interleaved, rows top first: one ``(height, width, 3)`` array, as decoders
and render targets give frames.
"""

from __future__ import annotations

import struct

import numpy as np

from torchgrade.base.budget import MAX_PIXELS, check_pixels

__all__ = ["DTYPES", "HEADER", "MAGIC", "frame_header", "pack_frame", "unpack_frame"]

HEADER = struct.Struct("<4sII4s")
MAGIC = b"TGF1"
DTYPES = {np.dtype(name).str: np.dtype(name) for name in ("uint8", "uint16", "float16", "float32")}


def pack_frame(frame: np.ndarray) -> bytes:
    """A ``(height, width, 3)`` array in the frame format.

    Examples:
        >>> body = pack_frame(np.zeros((2, 3, 3), np.uint8))
        >>> len(body), unpack_frame(body).shape
        (34, (2, 3, 3))
    """
    frame = np.ascontiguousarray(frame)
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype.newbyteorder("<").str not in DTYPES:
        raise ValueError(f"a frame is a (height, width, 3) array of {sorted(DTYPES)}, got {frame.shape} {frame.dtype}")
    frame = frame.astype(frame.dtype.newbyteorder("<"), copy=False)
    return HEADER.pack(MAGIC, frame.shape[0], frame.shape[1], frame.dtype.str.encode()) + frame.tobytes()


def frame_header(head: bytes, max_pixels: int) -> tuple:
    """``(height, width, dtype, body bytes)`` from a frame's 16-byte header, its pixels checked against the budget:
    what a server knows before it reads the samples.

    Examples:
        >>> frame_header(b"TGF1" + bytes(12), 1 << 20)
        Traceback (most recent call last):
        ...
        ValueError: a frame must be at least 1x1 pixels, got 0x0
    """
    if len(head) < HEADER.size:
        raise ValueError(f"a frame starts with a {HEADER.size}-byte header, got {len(head)} bytes")
    magic, height, width, dtype = HEADER.unpack_from(head)
    if magic != MAGIC:
        raise ValueError(f"a frame starts with {MAGIC!r}, got {magic!r}")
    check_pixels(height, width, "a frame", max_pixels)
    dtype = DTYPES.get(dtype.rstrip(b"\0").decode("ascii", "replace"))
    if dtype is None:
        raise ValueError(f"frame dtype must be one of {sorted(DTYPES)}")
    return height, width, dtype, HEADER.size + height * width * 3 * dtype.itemsize


def unpack_frame(body: bytes, max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """The ``(height, width, 3)`` array of a frame-format body; ``ValueError`` naming what is wrong."""
    height, width, dtype, expected = frame_header(body[: HEADER.size], max_pixels)
    if len(body) != expected:
        raise ValueError(f"a {height}x{width} {dtype} frame is {expected} bytes, got {len(body)}")
    return np.frombuffer(body, dtype, offset=HEADER.size).reshape(height, width, 3)
