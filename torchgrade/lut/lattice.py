"""The LUT lattice: sizes, coordinates, table layouts and domains.

``table`` has shape ``(size, size, size, 3)`` indexed ``[b, g, r, channel]``, so
``table.reshape(-1, 3)`` lists the entries with red fastest, the order of a ``.cube`` file. Lattice
point ``i`` of an axis sits at ``u = i / (size - 1)``: the end points are on the domain bounds, which is
``grid_sample``'s ``align_corners=True`` convention (and that of ``.cube`` files and OpenColorIO).

Examples:
    >>> lattice(2)[1, 0, 1].tolist()
    [1.0, 0.0, 1.0]
    >>> planar_table(identity_table(2)).shape
    torch.Size([3, 8])
"""

from __future__ import annotations

import numbers

import torch

__all__ = ["MIN_SIZE", "MAX_SIZE", "check_size", "lattice", "identity_table", "planar_table", "checked_domain"]

MIN_SIZE, MAX_SIZE = 2, 256
"""Lattice sizes accepted by :func:`~torchgrade.bake_lut` and :class:`~torchgrade.LUT3D` (points per axis)."""


def check_size(size) -> int:
    """Return ``size`` as an int, or raise ``ValueError`` unless it is an integer in [2, 256].

    Examples:
        >>> check_size(33)
        33
    """
    if isinstance(size, bool) or not isinstance(size, numbers.Integral) or not MIN_SIZE <= int(size) <= MAX_SIZE:
        raise ValueError(f"LUT size must be an integer from {MIN_SIZE} to {MAX_SIZE} (points per axis), got {size!r}")
    return int(size)


def lattice(size: int, dtype=torch.float64, device=None) -> torch.Tensor:
    """Lattice coordinates ``u`` in [0, 1], shape ``(size, size, size, 3)``: ``[b, g, r] -> (r, g, b) / (size - 1)``.

    Examples:
        >>> lattice(3).shape
        torch.Size([3, 3, 3, 3])
    """
    size = check_size(size)
    axis = torch.linspace(0.0, 1.0, size, dtype=dtype, device=device)
    b, g, r = torch.meshgrid(axis, axis, axis, indexing="ij")
    return torch.stack((r, g, b), dim=-1)


def identity_table(size: int, dtype=torch.float32) -> torch.Tensor:
    """The table that returns its lattice coordinates ``u``: an identity LUT on the domain [0, 1].

    Examples:
        >>> identity_table(2).dtype
        torch.float32
    """
    return lattice(size, torch.float64).to(dtype)


def planar_table(table: torch.Tensor) -> torch.Tensor:
    """``(S, S, S, 3)`` table as ``(3, S³)``: row ``c`` holds channel ``c`` at flat index ``r + S g + S² b``.

    Examples:
        >>> planar_table(identity_table(2))[0].tolist()
        [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0]
    """
    return table.reshape(-1, 3).t().contiguous()


MAX_CODE = 1e6
"""Largest magnitude of a lattice code value: a domain bound or a shaper curve's entry. A linear lattice of scene light
reaches 65504 (the non-finite policy's bound); beyond 1e6, float32 arithmetic on the lattice loses it (a domain of
±3e38 spans more than float32 holds, and every lookup came out 0)."""

MIN_DOMAIN_WIDTH = 1e-6
"""Narrowest lattice domain, relative to its bounds' size (at least 1): a narrower one divides by nearly nothing (a
domain of [0, 1e-45] gave infinite gradients)."""


def checked_domain(domain) -> tuple:
    """A lattice domain ``(min, max)`` as two float32 RGB triples, or ``ValueError`` unless finite, within
    ±:data:`MAX_CODE`, with max > min per channel by at least :data:`MIN_DOMAIN_WIDTH` of the bounds' size.

    Examples:
        >>> low, high = checked_domain((0.0, (1.0, 2.0, 4.0)))
        >>> high.tolist()
        [1.0, 2.0, 4.0]
    """
    try:
        low, high = domain
    except (TypeError, ValueError):
        raise ValueError(f"LUT domain must be a (min, max) pair, got {domain!r}") from None
    low, high = _rgb(low, "domain min"), _rgb(high, "domain max")
    if bool((high <= low).any()):
        raise ValueError(f"LUT domain max must exceed min, got {low.tolist()} and {high.tolist()}")
    if bool((torch.maximum(low.abs(), high.abs()) > MAX_CODE).any()):
        raise ValueError(f"LUT domain bounds must lie within ±{MAX_CODE:g}, got {low.tolist()} and {high.tolist()}")
    size = torch.maximum(torch.maximum(low.abs(), high.abs()), torch.ones(3))
    if bool(((high.double() - low.double()) < MIN_DOMAIN_WIDTH * size).any()):
        raise ValueError(f"LUT domain must be at least {MIN_DOMAIN_WIDTH:g} wide (relative to its bounds), got "
                         f"{low.tolist()} and {high.tolist()}")
    return low, high


def _rgb(value, name: str) -> torch.Tensor:
    try:
        t = torch.as_tensor(value, dtype=torch.float32).detach().reshape(-1)
    except (TypeError, ValueError, RuntimeError):
        raise ValueError(f"LUT {name} must be a finite number or RGB triple, got {value!r}") from None
    if t.numel() == 1:
        t = t.expand(3)
    if t.numel() != 3 or not bool(torch.isfinite(t).all()):
        raise ValueError(f"LUT {name} must be a finite number or RGB triple, got {value!r}")
    return t.clone()
