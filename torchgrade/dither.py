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

from .color import linear_to_srgb, srgb_to_linear
from .core import Param, check_image, check_range, is_constant, sanitize, scalar_param, to_input_dtype, working_dtype
from .params import ParamModule

DEFAULT_AMPLITUDE = 1.0 / 255.0
"""Half-width of the noise: one 8-bit sRGB code value."""
AMPLITUDE_RANGE = (0.0, 16.0 / 255.0)


def dither_pattern(size: int = 64, generator: Optional[torch.Generator] = None, dtype=torch.float32) -> torch.Tensor:
    """A ``(size, size)`` tile of triangular noise on [-1, 1]: ``u1 + u2 - 1`` of two uniform draws."""
    if size < 1:
        raise ValueError(f"dither pattern size must be at least 1, got {size}")
    uniform = torch.rand(2, size, size, generator=generator, dtype=torch.float64)
    return (uniform.sum(dim=0) - 1.0).to(dtype)


def tile_pattern(pattern: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """``pattern`` repeated over ``like``'s last two dimensions, as ``(H, W)``: pixel ``(y, x)`` takes ``pattern[y % S, x % S]``."""
    rows = torch.arange(like.shape[-2], device=like.device).remainder(pattern.shape[-2])
    columns = torch.arange(like.shape[-1], device=like.device).remainder(pattern.shape[-1])
    return pattern.to(device=like.device, dtype=like.dtype).index_select(-2, rows).index_select(-1, columns)


def dither(image: torch.Tensor, pattern: torch.Tensor, amplitude: Param = DEFAULT_AMPLITUDE) -> torch.Tensor:
    """``decode(clamp(encode(clamp(image, 0, 1)) + amplitude · noise, 0, 1))`` with the tiled ``pattern`` as noise.

    ``image`` is display-referred linear; ``encode``/``decode`` are the sRGB transfer functions.
    ``amplitude`` 0 returns ``image`` itself.
    """
    check_image(image)
    if is_constant(amplitude, 0.0):
        return image
    x = sanitize(working_dtype(image)).clamp(0.0, 1.0)
    noise = tile_pattern(pattern, x) * scalar_param(amplitude, x, "amplitude")
    return to_input_dtype(srgb_to_linear((linear_to_srgb(x) + noise).clamp(0.0, 1.0)), image)


class Dither(ParamModule):
    """Deband dithering layer, after tone mapping: ``Dither(amplitude=1/255, seed=0, size=64)``.

    ``amplitude`` (number, ``(B,)`` tensor or ``nn.Parameter``, 0..16/255) is the half-width of the
    triangular noise in sRGB values (1/255: one 8-bit code); 0 makes the layer an identity. ``seed``
    (an int) draws the noise tile, so the same seed gives the same noise; the functional
    :func:`dither` takes any tile, for instance from :func:`dither_pattern` with a ``torch.Generator``.
    """

    def __init__(self, amplitude: Param = DEFAULT_AMPLITUDE, seed: int = 0, size: int = 64):
        super().__init__()
        check_range(amplitude, "amplitude", *AMPLITUDE_RANGE)
        if isinstance(seed, bool) or not isinstance(seed, int):
            raise TypeError(f"seed must be an int, got {type(seed).__name__}")
        self.set_param("amplitude", amplitude)
        self.seed, self.size = seed, int(size)
        self.register_buffer("pattern", dither_pattern(self.size, torch.Generator().manual_seed(seed)), persistent=False)

    @property
    def is_identity(self) -> bool:
        """True at amplitude 0 (then skipped by ``PostFX`` and not exported)."""
        return is_constant(self.amplitude, 0.0)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return dither(image, self.pattern, self.amplitude)

    def config(self) -> dict:
        """Amplitude, seed and tile size as plain values."""
        return {"amplitude": self.plain_params()["amplitude"], "seed": self.seed, "size": self.size}

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.config().items())
