"""What every tone mapping curve shares: the input limit, the display clip and the registry entry.

Every curve clamps its input to ``[0, limit]`` first (:func:`limited`) and ends with :func:`display`,
which clips to [0, 1] unless the caller asks for the unclipped display value (``clip=False``, as a
LUT that clips after its lookup does).
"""

from __future__ import annotations

import inspect
from typing import Callable, Mapping, NamedTuple, Optional

import torch

from ..base.planes import apply_matrix
from ..base.controls import Control

__all__ = ["TONEMAP_INPUT_LIMIT", "WHITE_POINT_RANGE", "ToneMapper", "limited", "display", "apply_rows", "no_tonemap"]

TONEMAP_INPUT_LIMIT = 60.0
"""Inputs are clamped to this before tone mapping (Catlike Coding, HDR §3.3: 'a limit of 60')."""

WHITE_POINT_RANGE = (1e-3, 1e4)
"""Valid ``[low, high]`` of ``white_point``, which means the same in every mode that takes it."""


class ToneMapper(NamedTuple):
    """One tone mapping mode: its ``curve``, its ``controls`` ``{name: Control(default, range)}`` and what a stage
    must ``prepare`` when its controls are set (tables searched per value, built outside any graph), or ``None``.

    ``curve(image, clip=True, **controls)`` takes scene-referred linear Rec.709, sanitized
    (:func:`~torchgrade.base.images.sanitize`), and returns display-referred linear Rec.709, clipped to [0, 1] when
    ``clip``; ``prepare(**controls)`` returns what the stage keeps so that what was built stays built while the stage
    lives. A curve that also stands alone and sanitizes its input itself (ACES 2.0's) takes ``nan_free``
    (``takes_nan_free``), so its input's NaN pass is not made twice; a curve that computes on the image's planes where
    a compiler fuses them (:func:`~torchgrade.runtime.strips.pixelwise`) takes ``planes`` (``takes_planes``).

    Examples:
        >>> entry = ToneMapper.of(no_tonemap)
        >>> entry.controls
        {}
    """

    curve: Callable[..., torch.Tensor]
    controls: dict
    prepare: Optional[Callable[..., object]] = None
    takes_nan_free: bool = False
    takes_planes: bool = False

    @classmethod
    def of(cls, curve: Callable[..., torch.Tensor], prepare: Optional[Callable[..., object]] = None, *,
           takes_nan_free: bool = False, takes_planes: bool = False, **ranges: tuple) -> "ToneMapper":
        """The entry of ``curve`` with a control per ``ranges`` item, its default from ``curve``'s own signature, and
        the keywords it takes (``nan_free``, ``planes``) as its entry states them.

        Examples:
            >>> def lift(image, amount=0.5, clip=True):
            ...     return display(image + amount, clip)
            >>> ToneMapper.of(lift, amount=(0.0, 1.0)).controls["amount"]
            Control(default=0.5, range=(0.0, 1.0), kind='number')
        """
        return cls.with_ranges(curve, ranges, prepare, takes_nan_free=takes_nan_free, takes_planes=takes_planes)

    @classmethod
    def with_ranges(cls, curve: Callable[..., torch.Tensor], ranges: Mapping[str, tuple],
                    prepare: Optional[Callable[..., object]] = None, *, takes_nan_free: bool = False,
                    takes_planes: bool = False) -> "ToneMapper":
        """:meth:`of` with the ranges as one mapping ``{name: (low, high)}`` (a curve's table of them)."""
        defaults = inspect.signature(curve).parameters
        controls = {name: Control(defaults[name].default, allowed) for name, allowed in ranges.items()}
        return cls(curve, controls, prepare, takes_nan_free, takes_planes)


def limited(image: torch.Tensor, limit=TONEMAP_INPUT_LIMIT) -> torch.Tensor:
    """``clamp(image, 0, limit)``: black for negative (out-of-gamut) values, ``limit`` a number or a tensor.

    Examples:
        >>> limited(torch.tensor([-1.0, 0.5, 100.0])).tolist()
        [0.0, 0.5, 60.0]
    """
    if isinstance(limit, torch.Tensor):  # torch.clamp takes two numbers or two tensors: a tensor limit, two passes
        return image.clamp_min(0.0).clamp_max(limit)
    return image.clamp(0.0, limit)


def display(image: torch.Tensor, clip: bool) -> torch.Tensor:
    """A curve's last step: the display range [0, 1] when ``clip``, else the curve's own values.

    Examples:
        >>> display(torch.tensor([-0.5, 1.5]), clip=True).tolist()
        [0.0, 1.0]
        >>> display(torch.tensor([-0.5, 1.5]), clip=False).tolist()
        [-0.5, 1.5]
    """
    return image.clamp(0.0, 1.0) if clip else image


def apply_rows(rows, image: torch.Tensor) -> torch.Tensor:
    """Apply a constant 3x3 matrix, given as rows, to every pixel of ``(..., 3, H, W)``.

    Examples:
        >>> apply_rows(((0, 1, 0), (1, 0, 0), (0, 0, 1)), torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1)).flatten().tolist()
        [2.0, 1.0, 3.0]
    """
    return apply_matrix(torch.tensor(rows, dtype=image.dtype, device=image.device), image)


def no_tonemap(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """No curve: the display simply clips to [0, 1].

    Examples:
        >>> no_tonemap(torch.tensor([0.5, 3.0]).reshape(1, 2, 1).expand(3, 2, 1)).flatten().tolist()
        [0.5, 1.0, 0.5, 1.0, 0.5, 1.0]
    """
    return display(image, clip)
