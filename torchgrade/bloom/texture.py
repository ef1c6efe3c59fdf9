"""Textures a bloom takes besides the image: lens dirt and convolution kernels, ``(C, h, w)`` with C = 1 or 3."""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["as_texture", "check_texture", "resampled"]


def as_texture(value):
    """A texture given as nested lists (a config) as a float32 tensor; tensors and None as they are.

    Examples:
        >>> as_texture([[[1, 2]]])
        tensor([[[1., 2.]]])
    """
    return value if value is None or isinstance(value, torch.Tensor) else torch.tensor(value, dtype=torch.float32)


def check_texture(texture, name: str, odd_sides: bool = False, values: bool = True) -> None:
    """Raise unless ``texture`` is None or a finite floating ``(C, h, w)`` tensor with C = 1 or 3.

    ``odd_sides``: also require odd sides, so that the texture's centre is a pixel (a kernel). ``values=False``: its
    shape and dtype only, not its values (a functional call reads no tensor back; a stage checks when it is set).

    Examples:
        >>> check_texture(torch.ones(2, 4, 4), "dirt")
        Traceback (most recent call last):
        ...
        ValueError: dirt must have shape (1 or 3, h, w), got (2, 4, 4)
    """
    if texture is None:
        return
    if not isinstance(texture, torch.Tensor) or not texture.is_floating_point():
        raise TypeError(f"{name} must be a floating-point tensor (C, h, w), got {getattr(texture, 'dtype', type(texture).__name__)}")
    if texture.dim() != 3 or texture.shape[0] not in (1, 3) or texture.numel() == 0:
        raise ValueError(f"{name} must have shape (1 or 3, h, w), got {tuple(texture.shape)}")
    if values and not bool(torch.isfinite(texture).all()):
        raise ValueError(f"{name} must be finite")
    if odd_sides and (texture.shape[-2] % 2 == 0 or texture.shape[-1] % 2 == 0):
        raise ValueError(f"{name} must have odd sides so that its centre is a pixel, got {tuple(texture.shape)}")


def resampled(texture: torch.Tensor, size, like: torch.Tensor) -> torch.Tensor:
    """A ``(C, h, w)`` texture resampled bilinearly (stretched) to ``size``, as ``(1, C, H, W)`` in ``like``'s dtype.

    Examples:
        >>> resampled(torch.ones(1, 2, 2), (3, 5), torch.zeros(1)).shape
        torch.Size([1, 1, 3, 5])
    """
    texture = texture.to(device=like.device, dtype=like.dtype).unsqueeze(0)
    return F.interpolate(texture, size=size, mode="bilinear", align_corners=False)
