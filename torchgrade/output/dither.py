"""Deband dithering of display-referred output: triangular noise of ±1 code in sRGB, and ``Dither``.

A tone-mapped frame quantised to 8 bits bands on smooth gradients. Adding noise of triangular
probability density (TPDF, the sum of two uniform variables: zero mean, variance ``a²/6`` for a
half-width ``a``) to the sRGB-encoded values before quantisation turns the bands into fine noise
whose local mean is the unquantised value, and makes the quantisation error independent of the
signal in mean and variance.

The noise is a fixed ``size x size`` tile (default 64, like the tiled blue-noise textures engines
dither with) drawn from a seeded generator and repeated over the frame, one value per pixel shared
by the three channels (no colour noise). It is the same at every call, for every sample of a
batch, and in an exported ONNX graph, where the tile is a constant and the tiling is index
arithmetic on the frame's size (every resolution works).

The layer takes display-referred linear values (a :class:`~torchgrade.ToneMap`'s output): it clamps
to [0, 1], encodes to sRGB, adds ``amplitude · noise``, clamps to [0, 1] again and decodes back to
display-referred linear, so the rest of the pipeline is unchanged.
"""

from __future__ import annotations

from typing import Optional

import torch

from ..base.controls import Control, check_given
from ..base.images import check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import Param, is_constant, scalar_param
from ..color import linear_to_srgb, srgb_to_linear

__all__ = ["dither", "dithered", "dither_pattern", "tile_pattern", "DEFAULT_AMPLITUDE", "DITHER_CONTROLS"]

DEFAULT_AMPLITUDE = 1.0 / 255.0
"""Half-width of the noise: one 8-bit sRGB code value."""

DITHER_CONTROLS = {
    "amplitude": Control(DEFAULT_AMPLITUDE, (0.0, 16.0 / 255.0)),
    # torch.Generator.manual_seed's range.
    "seed": Control(0, (-(2**63), 2**64 - 1)),
    "size": Control(64, (1, 4096)),
}
""":class:`~torchgrade.Dither`'s controls: the noise's half-width, and the seed and side of its tile."""


def dither_pattern(size: int = 64, generator: Optional[torch.Generator] = None, dtype=torch.float32) -> torch.Tensor:
    """A ``(size, size)`` tile of triangular noise on [-1, 1]: ``u1 + u2 - 1`` of two uniform draws.

    Examples:
        >>> tile = dither_pattern(8, torch.Generator().manual_seed(0))
        >>> tile.shape, bool(tile.abs().max() <= 1.0)
        (torch.Size([8, 8]), True)
    """
    if size < 1:
        raise ValueError(f"dither pattern size must be at least 1, got {size}")
    uniform = torch.rand(2, size, size, generator=generator, dtype=torch.float64)
    return (uniform.sum(dim=0) - 1.0).to(dtype)


def tile_pattern(pattern: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """``pattern`` repeated over ``like``'s last two dimensions, as ``(H, W)``: pixel ``(y, x)`` takes ``pattern[y % S, x % S]``.

    Examples:
        >>> tile_pattern(torch.tensor([[1.0, 2.0], [3.0, 4.0]]), torch.empty(3, 3, 3)).tolist()
        [[1.0, 2.0, 1.0], [3.0, 4.0, 3.0], [1.0, 2.0, 1.0]]
    """
    rows = torch.arange(like.shape[-2], device=like.device).remainder(pattern.shape[-2])
    columns = torch.arange(like.shape[-1], device=like.device).remainder(pattern.shape[-1])
    return pattern.to(device=like.device, dtype=like.dtype).index_select(-2, rows).index_select(-1, columns)


def dither(image: torch.Tensor, pattern: torch.Tensor, amplitude: Param = DEFAULT_AMPLITUDE) -> torch.Tensor:
    """``decode(clamp(encode(clamp(image, 0, 1)) + amplitude · noise, 0, 1))`` with the tiled ``pattern`` as noise.

    ``image`` is display-referred linear; ``encode``/``decode`` are the sRGB transfer functions.
    ``amplitude`` 0 returns ``image`` itself; as a number it is checked as :class:`~torchgrade.Dither` checks it
    (:data:`DITHER_CONTROLS`).

    Examples:
        >>> image = torch.full((1, 3, 4, 4), 0.5)
        >>> out = dither(image, dither_pattern(4, torch.Generator().manual_seed(0)))
        >>> bool((out - image).abs().max() < 0.01), dither(image, torch.ones(4, 4), 0.0) is image
        (True, True)
        >>> dither(image, torch.ones(4, 4), 0.5)
        Traceback (most recent call last):
        ...
        ValueError: amplitude must lie in [0.0, 0.06274509803921569], got 0.5
    """
    check_given(DITHER_CONTROLS, {"amplitude": amplitude}, "Dither")
    return dithered(image, pattern, amplitude)


def dithered(image: torch.Tensor, pattern: torch.Tensor, amplitude: Param = DEFAULT_AMPLITUDE, *,
             nan_free: bool = False) -> torch.Tensor:
    """:func:`dither` without checking ``amplitude``: for :class:`~torchgrade.Dither`, which checked it when it was
    set. ``nan_free``: ``image`` holds no NaN (:func:`~torchgrade.base.images.sanitize`).

    Examples:
        >>> image = torch.full((1, 3, 4, 4), 0.5)
        >>> torch.equal(dithered(image, torch.ones(4, 4), 0.01), dither(image, torch.ones(4, 4), 0.01))
        True
    """
    check_image(image)
    if is_constant(amplitude, 0.0):
        return image
    x = sanitize(working_dtype(image), nan_free=nan_free).clamp(0.0, 1.0)
    noise = tile_pattern(pattern, x) * scalar_param(amplitude, x, "amplitude")
    return to_input_dtype(srgb_to_linear((linear_to_srgb(x) + noise).clamp(0.0, 1.0)), image)
