"""The serving example's limits, each stated once: ``serve.py``'s flags default to them and the replica enforces them."""

from __future__ import annotations

from dataclasses import dataclass, fields

from torchgrade.base.budget import MAX_PIXELS

__all__ = ["Limits"]


@dataclass(frozen=True)
class Limits:
    """What one replica admits, with the reasons for the defaults.

    Examples:
        >>> Limits(max_batch=0)
        Traceback (most recent call last):
        ...
        ValueError: max_batch must be at least 1, got 0
    """

    max_bytes: int = 64 << 20
    """Largest request body (413 beyond, from ``Content-Length`` before reading; 411 without one)."""
    max_pixels: int = MAX_PIXELS
    """Largest frame or image, from its header before decoding (400); lowered to what ``max_bytes`` / 3 and the
    memory budget allow."""
    max_batch: int = 8
    wait_ms: float = 5.0
    max_ongoing: int = 16
    """Requests at the replica at once (Ray Serve's ``max_ongoing_requests``)."""
    max_queued: int = 64
    """Requests queued at the proxy beyond those (``max_queued_requests``); 503 beyond, before the body is read."""
    timeout_s: float = 30.0
    """The proxy's end-to-end request timeout (``request_timeout_s``, 408); a frame still waiting then is not graded."""
    memory_mib: int = 4096
    """The replica's resident memory at its peak: a request waits until its cost fits (413 if it never can)."""
    min_body_rate: float = float(128 << 10)
    """Bytes a second a body must keep up with after ``body_grace_s`` (408 otherwise): 1 Mbit/s, a slow uplink; a
    client sending slower holds a request slot that others need. A larger body must keep the pace that ends it within
    ``timeout_s`` (``body.py``)."""
    body_grace_s: float = 1.0

    def __post_init__(self):
        for field in fields(self):
            least = {"max_queued": 0, "wait_ms": 0, "body_grace_s": 0, "max_bytes": 16}.get(field.name, 1)
            if not getattr(self, field.name) >= least:
                raise ValueError(f"{field.name} must be at least {least}, got {getattr(self, field.name)}")
        object.__setattr__(self, "max_pixels", min(self.max_pixels, self.max_bytes // 3))
