"""Soft-light blends and split toning (Unity's ``SoftLight`` and ``ColorGradeSplitToning``): tints blended in gamma
2.2, by channel where the tints are numbers.
"""

from __future__ import annotations

import torch

from ..base.params import Param, color_param, is_constant, scalar_param
from ..base.planes import each_plane, joined
from ..color import luminance, safe_pow, safe_sqrt

__all__ = ["soft_light", "split_toning"]


def soft_light(base: torch.Tensor, blend: torch.Tensor) -> torch.Tensor:
    """Soft-light blend (Unity ``SoftLight``, after Adobe): below 0.5 ``2ab + a²(1 - 2b)``, else
    ``sqrt(a)(2b - 1) + 2a(1 - b)``.

    Examples:
        >>> soft_light(torch.tensor([0.3]), torch.tensor([0.5])).tolist()  # a 0.5 blend changes nothing
        [0.30000001192092896]
    """
    return torch.where(blend >= 0.5, _lighten(base, blend), _darken(base, blend))


def _darken(base: torch.Tensor, blend: torch.Tensor) -> torch.Tensor:
    """Soft light below a blend of 0.5: ``2ab + a²(1 - 2b)``."""
    return 2.0 * base * blend + base * base * (1.0 - 2.0 * blend)


def _lighten(base: torch.Tensor, blend: torch.Tensor) -> torch.Tensor:
    """Soft light from a blend of 0.5 up: ``sqrt(a)(2b - 1) + 2a(1 - b)``."""
    return safe_sqrt(base) * (2.0 * blend - 1.0) + 2.0 * base * (1.0 - blend)


def _soft_light_by_channel(gamma, weights: tuple, offsets: tuple):
    """Soft-light blends of ``gamma`` with tints ``0.5 + offset · weight`` given by constant per-channel ``offsets``.

    With ``weight`` in [0, 1] a channel's blend stays on the side of 0.5 its offset's sign gives, so each channel is
    blended by that branch of :func:`soft_light` alone, written with ``s = 2 blend - 1 = 2 offset weight``:
    ``a + s(√a - a)`` (:func:`_lighten`) and ``a + s·a(1 - a)`` (:func:`_darken`), one multiply-add each; an offset of
    0 blends with 0.5 exactly, where both branches return the base, and is skipped. The image's planes (a tuple) are
    returned as planes.

    Examples:
        >>> base, t = torch.rand(1, 3, 2, 2), torch.rand(1, 1, 2, 2)
        >>> tint = 0.5 + torch.tensor([-0.2, 0.0, 0.3]).reshape(3, 1, 1) * t
        >>> bool(torch.allclose(_soft_light_by_channel(base, (t,), ((-0.2, 0.0, 0.3),)), soft_light(base, tint), atol=1e-6))
        True
    """
    on_planes = isinstance(gamma, tuple)
    planes = _blend_planes(gamma if on_planes else gamma.split(1, dim=-3), weights, offsets)
    return tuple(planes) if on_planes else torch.cat(planes, dim=-3)


def _blend_planes(planes, weights: tuple, offsets: tuple) -> list:
    """Plane ``c`` blended with each weight in turn, ``a + 2 offset · weight · (a(1 - a) or √a - a)`` by the sign of
    that weight's offset ``offsets[i][c]``, skipped where it is 0: the steps of :func:`_soft_light_by_channel`."""
    blended = []
    for c, plane in enumerate(planes):
        for weight, channel_offsets in zip(weights, offsets):
            offset = channel_offsets[c]
            if offset != 0.0:
                shift = torch.addcmul(plane, plane, plane, value=-1.0) if offset < 0.0 else safe_sqrt(plane) - plane
                plane = torch.addcmul(plane, weight, shift, value=2.0 * offset)
        blended.append(plane)
    return blended


def _soft_light_masked(base: torch.Tensor, weight: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """:func:`soft_light` with the tint ``0.5 + offset · weight``, for offsets that are tensors (per sample, learnable).

    With ``weight`` in [0, 1] the blend's side of 0.5 is the offset's sign, so the branch is picked per channel by
    ``m = [offset > 0]`` instead of per pixel (an offset of 0 blends with 0.5, where both branches give the base):
    ``a + s(m √a + a((1 - 2m) - (1 - m) a))`` with ``s = 2 offset weight`` is :func:`_lighten` for ``m = 1`` and
    :func:`_darken` for ``m = 0``, exactly (a 0/1 factor of a finite value): no select over the frame.

    Examples:
        >>> base, t, offset = torch.rand(2, 3, 2, 2), torch.rand(2, 1, 2, 2), torch.tensor([[-0.2, 0.0, 0.3], [0.1, -0.4, 0.0]])
        >>> offset = offset.reshape(2, 3, 1, 1)
        >>> bool(torch.allclose(_soft_light_masked(base, t, offset), soft_light(base, 0.5 + offset * t), atol=1e-6))
        True
    """
    lighter = (offset > 0.0).to(base.dtype)
    shift = lighter * safe_sqrt(base) + base * ((1.0 - 2.0 * lighter) - (1.0 - lighter) * base)
    return base + 2.0 * offset * weight * shift


def split_toning(
    image: torch.Tensor, shadows=(0.5, 0.5, 0.5), highlights=(0.5, 0.5, 0.5), balance: Param = 0.0, luminance_weights="rec709"
) -> torch.Tensor:
    """Split toning in gamma 2.2 space (Unity ``ColorGradeSplitToning``).

    ``t = saturate(Y(saturate(c)) + balance/100)``; the shadow tint ``lerp(0.5, shadows, 1 - t)`` and the
    highlight tint ``lerp(0.5, highlights, t)`` are soft-light blended in turn. Grey 0.5 tints are neutral. An image
    given as its three planes (a tuple, :func:`~torchgrade.runtime.strips.pixelwise`) is toned as planes
    where the tints are numbers, and joined into one image where they are tensors.

    Examples:
        >>> image = torch.rand(3, 2, 2)
        >>> bool(torch.allclose(split_toning(image), image, atol=1e-5))  # grey tints: neutral
        True
    """
    plain = _plain_offsets(shadows), _plain_offsets(highlights)
    if None in plain:
        image = joined(image)  # tensor colours blend the frame
    gamma = each_plane(lambda plane: safe_pow(plane, 1.0 / 2.2), image)
    t = luminance(each_plane(lambda plane: plane.clamp(0.0, 1.0), gamma), luminance_weights)
    if not is_constant(balance, 0.0):
        t = t + scalar_param(balance, t, "split_balance") * 0.01
    t = t.clamp(0.0, 1.0)
    if None not in plain:
        return each_plane(lambda plane: safe_pow(plane, 2.2), _soft_light_by_channel(gamma, (1.0 - t, t), plain))
    offsets = (color_param(shadows, image, "split_shadows") - 0.5, color_param(highlights, image, "split_highlights") - 0.5)
    return safe_pow(_toned(gamma, t, *offsets), 2.2)


def _toned(gamma: torch.Tensor, t: torch.Tensor, shadows: torch.Tensor, highlights: torch.Tensor) -> torch.Tensor:
    """The two soft-light blends of :func:`split_toning` with the tints ``0.5 + shadows (1 - t)`` and
    ``0.5 + highlights t`` (offsets from grey, tensors), the branch of each picked per channel
    (:func:`_soft_light_masked`).

    Examples:
        >>> gamma, t = torch.rand(1, 3, 2, 2), torch.rand(1, 1, 2, 2)
        >>> shadows, highlights = torch.tensor([-0.2, 0.0, 0.3]).reshape(3, 1, 1), torch.tensor([0.1, -0.4, 0.0]).reshape(3, 1, 1)
        >>> expected = soft_light(soft_light(gamma, 0.5 + shadows * (1.0 - t)), 0.5 + highlights * t)
        >>> bool(torch.allclose(_toned(gamma, t, shadows, highlights), expected, atol=1e-6))
        True
    """
    return _soft_light_masked(_soft_light_masked(gamma, 1.0 - t, shadows), t, highlights)


def _plain_offsets(color):
    """A split-toning colour given as three numbers, as its offsets from neutral grey ``c - 0.5`` in Python (the branch
    each channel's blend takes is then known without reading the device); ``None`` for a tensor.

    Examples:
        >>> _plain_offsets((0.45, 0.5, 0.56)), _plain_offsets(torch.tensor([0.5, 0.5, 0.5]))
        ((-0.04999999999999999, 0.0, 0.06000000000000005), None)
    """
    if isinstance(color, torch.Tensor) or len(color) != 3 or not all(isinstance(c, (int, float)) for c in color):
        return None
    return tuple(float(c) - 0.5 for c in color)
