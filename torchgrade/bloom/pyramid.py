"""The bloom pyramid: depth, 2x2 sum pooling, mirror padding, Gaussian blur, upsampling, B-spline refinement.

**Light is conserved, borders included.** The pyramid works on light *sums* (each pixel holds the
light of the full-resolution pixels it covers) and every resampling step keeps the sum:

* pooling is a 2x2 sum (blocks at odd edges sum fewer pixels);
* blurs run over the frame extended by its mirror image about the edge (half-sample symmetric):
  with a symmetric kernel that operator is symmetric and its rows sum to 1, so its columns do too,
  and every pixel's light stays in the frame; clamped edges (the usual texture sampling) magnify
  edge pixels instead, and zero padding loses their light;
* bilinear 2x upsampling with ``align_corners=False`` and clamped edges gives every coarse pixel
  weights summing to the number of fine pixels it was pooled from (the crop of an odd last row or
  column included), so upsampling the block means ``m / count`` keeps the sum.

Sizes come from tensor shapes, so a traced graph keeps working at every frame size, except
:func:`pyramid_depth` (Python ints, as in kornia's pyramid functions) and :func:`mirror_pad`'s count
of reflections for levels narrower than the blur radius.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..base.core import is_tracing
from ..runtime import device_cached, is_exporting, policy_for

__all__ = [
    "BLUR_SIGMA", "BLUR_TAPS", "ANAMORPHIC_TAPS", "BSPLINE_AFTER_BILINEAR", "pyramid_depth", "active_levels",
    "sum_pool", "block_counts", "mirror_pad", "pyramid_blur", "anamorphic_sigma", "bspline_refine", "upsample",
    "nearest_upsample", "glow_pyramid",
]

BLUR_SIGMA = 1.69
"""Standard deviation (in level pixels) of the pyramid blur: that of Unity's 9-tap kernel (binomial
coefficients of order 12, the outer three dropped), whose variance is ``2 * 5808 / 4070 = 2.854``."""
BLUR_TAPS = 9
ANAMORPHIC_TAPS = 23
"""Taps of the stretched blur: radius 11 covers 3 sigma at the widest stretch (``2 * 1.69``)."""

BSPLINE_AFTER_BILINEAR = (1.0 / 96, 24.0 / 96, 46.0 / 96, 24.0 / 96, 1.0 / 96)
"""Cubic B-spline 2x upsampling is bilinear 2x upsampling followed by this filter (per axis).

At 2x with half-pixel centres the B-spline weights are ``[1, 27, 121, 235, 235, 121, 27, 1] / 192``
on the zero-stuffed signal, which factors as bilinear ``[1, 3, 3, 1] / 4`` times this kernel. The
B-spline (Unity's ``SampleTexture2DBicubic``) is non-negative, so unlike Keys' bicubic (PyTorch's
``bicubic``) it never makes negative light from non-negative light, and needs no clamp."""


def pyramid_depth(height: int, width: int, max_iterations: int, downscale_limit: int) -> int:
    """Number of blurred levels below the half-resolution prefilter (Unity ``DoBloom``'s loop).

    As in Unity, level ``n`` counts while both ``floor(side / 2^(n+1))`` are at least
    ``downscale_limit``; the level tensors themselves round sizes up (:func:`sum_pool`) so that no
    edge pixel is dropped. Depth 0 (a side under ``4 * downscale_limit`` pixels, or
    ``max_iterations = 0``) means no bloom.

    Sizes are Python ints here, so tracing freezes the depth: an exporter serving every resolution
    from one graph fixes the depth itself (:class:`~torchgrade.bloom.FixedDepthBloom`).

    Examples:
        >>> pyramid_depth(1080, 1920, 16, 2)
        8
        >>> pyramid_depth(7, 7, 16, 2)
        0
    """
    depth, h, w = 0, height // 2, width // 2
    while depth < max_iterations:
        h, w = h // 2, w // 2
        if min(h, w) < downscale_limit:
            break
        depth += 1
    return depth


def active_levels(image: torch.Tensor, max_iterations: int, downscale_limit: int) -> torch.Tensor:
    """:func:`pyramid_depth` as a 0-d tensor: while tracing, computed from ``image``'s runtime shape (an exported
    graph keeps it symbolic); otherwise made once per frame size on ``image``'s device, so that the selects it drives
    copy nothing from the host (``torch.where`` copies a CPU condition to the device at every call).

    Level ``n`` counts when ``floor(side / 2^(n+1)) >= downscale_limit`` for both sides, that is when
    ``min(height, width) >= downscale_limit · 2^(n+1)``.

    Examples:
        >>> int(active_levels(torch.zeros(1, 3, 1080, 1920), 16, 2))
        8
    """
    if not is_tracing():
        return _levels_on(*image.shape[-2:], max_iterations, downscale_limit, image.device)
    smaller_side = torch._shape_as_tensor(image)[-2:].min()
    thresholds = downscale_limit * 2 ** torch.arange(2, max_iterations + 2)
    return (smaller_side >= thresholds).sum()


@device_cached
def _levels_on(height: int, width: int, max_iterations: int, downscale_limit: int, device: torch.device) -> torch.Tensor:
    return torch.tensor(pyramid_depth(height, width, max_iterations, downscale_limit), device=device)


def sum_pool(light: torch.Tensor) -> torch.Tensor:
    """2x2 sums, rounding the size up: blocks at odd edges sum the pixels they have.

    Four strided views added together: on CPU about 3 times faster than ``F.avg_pool2d``. Where the device's
    policy takes library kernels (CUDA: one launch instead of four) ``F.avg_pool2d`` with ``divisor_override=1``
    is used instead, and for export: it exports as one ``AveragePool`` of the frame padded to even sides
    (:mod:`torchgrade.onnx.symbolics`) instead of four strided slices and three sums (bench_onnx's bloom row),
    and OpenVINO accepts it on a 1-pixel side, where it refuses a ceil-mode pool.

    Examples:
        >>> sum_pool(torch.ones(1, 1, 3, 4))
        tensor([[[[4., 4.],
                  [2., 2.]]]])
    """
    if is_exporting() or (not is_tracing() and policy_for(light.device).filters_as_kernels):
        return F.avg_pool2d(light, 2, ceil_mode=True, divisor_override=1)
    odd_height, odd_width = light.shape[-2] % 2, light.shape[-1] % 2
    if odd_height or odd_width or is_tracing():  # F.pad copies the frame even when it adds nothing
        light = F.pad(light, (0, odd_width, 0, odd_height))
    return light[..., ::2, ::2] + light[..., 1::2, ::2] + light[..., ::2, 1::2] + light[..., 1::2, 1::2]


def block_counts(height: int, width: int, like: torch.Tensor) -> torch.Tensor:
    """How many pixels of a ``height x width`` level each pixel of the 2x2-pooled level covers (1, 2 or 4): a copy,
    which the caller may change.

    Examples:
        >>> block_counts(3, 4, torch.zeros(1))
        tensor([[[[4., 4.],
                  [2., 2.]]]])
    """
    return shared_block_counts(height, width, like).clone()


def shared_block_counts(height: int, width: int, like: torch.Tensor) -> torch.Tensor:
    """:func:`block_counts` as the device constant every pooling shares (made once per size, dtype and device), never
    to be modified in place.

    Examples:
        >>> shared_block_counts(3, 4, torch.zeros(1)) is shared_block_counts(3, 4, torch.zeros(1))
        True
    """
    return _block_counts(height, width, like.device, like.dtype)


@device_cached
def _block_counts(height: int, width: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    def per_axis(side):
        # Integer arithmetic, cast once: an exported graph run at reduced precision (OpenVINO's bf16
        # default) cannot represent sizes above 256 exactly, and a float count of 0 divides by zero.
        start = 2 * torch.arange(-(-side // 2), device=device)
        return (side - start).clamp(max=2)

    counts = per_axis(height)[:, None] * per_axis(width)[None, :]
    return counts.to(dtype).expand(1, 1, -1, -1)


def mirror_pad(light: torch.Tensor, radius: int) -> torch.Tensor:
    """Extend the frame by ``radius`` pixels on every side with its mirror image about the edge.

    Half-sample symmetric extension (``c b a | a b c | c b a``), periodic with period ``2 · side``
    so it repeats when the frame is narrower than ``radius``. A symmetric kernel applied to it is a
    symmetric, row-stochastic operator, hence also column-stochastic: every pixel keeps all of its
    light inside the frame, and a uniform frame stays uniform. Written as index arithmetic on the
    tensor's own sizes, so a traced graph (ONNX) keeps working at every frame size; where the device's
    policy takes library kernels (one launch each) the two axes are one gather over the flattened plane.

    Examples:
        >>> mirror_pad(torch.tensor([[[[1.0, 2.0, 3.0]]]]), 2)[0, 0, 0]
        tensor([2., 1., 1., 2., 3., 3., 2.])
    """
    height, width = light.shape[-2:]
    if not is_tracing() and policy_for(light.device).filters_as_kernels:
        index = _mirror_plane_index(height, width, radius, light.device)
        return light.flatten(-2).index_select(-1, index).unflatten(-1, (height + 2 * radius, width + 2 * radius))
    for axis in (-2, -1):
        light = light.index_select(axis, _mirror_index(light.shape[axis], radius, light.device))
    return light


@device_cached
def _mirror_index(side: int, radius: int, device: torch.device) -> torch.Tensor:
    """The source of each pixel of a side of ``side`` pixels extended by ``radius`` (:func:`mirror_pad`)."""
    position = torch.arange(-radius, side + radius, device=device).remainder(2 * side)
    return torch.where(position < side, position, 2 * side - 1 - position)


@device_cached
def _mirror_plane_index(height: int, width: int, radius: int, device: torch.device) -> torch.Tensor:
    """The source of each pixel of the extended plane in the flattened ``height x width`` plane (:func:`mirror_pad`)."""
    rows, columns = _mirror_index(height, radius, device), _mirror_index(width, radius, device)
    return (rows[:, None] * width + columns[None, :]).flatten()


def pyramid_blur(light: torch.Tensor, sigma=None) -> torch.Tensor:
    """The pyramid blur: ``kornia.filters.gaussian_blur2d`` over the mirrored frame (so it keeps the light).

    ``sigma`` ``(N or 1, 2)`` as ``(sigma_y, sigma_x)`` selects the 23-tap stretched blur; ``None`` the 9-tap one.

    Examples:
        >>> light = torch.zeros(1, 3, 6, 6); light[..., 0, 0] = 1.0
        >>> round(float(pyramid_blur(light).sum()), 4)
        3.0
    """
    taps = BLUR_TAPS if sigma is None else ANAMORPHIC_TAPS
    radius = taps // 2
    padded = mirror_pad(light, radius)
    import kornia.filters  # imported at the first blur: kornia takes longer to import than torchgrade itself

    policy = policy_for(light.device)
    if policy.filters_as_kernels:
        small = policy.one_kernel_blur_pixels is not None and light.shape[-2] * light.shape[-1] <= policy.one_kernel_blur_pixels
        if sigma is None and small:
            planes = padded.reshape((-1, 1) + padded.shape[-2:])
            return F.conv2d(planes, _gaussian_kernel_2d(taps, BLUR_SIGMA, light.device, light.dtype)).reshape(light.shape)
        if sigma is None:
            kernel_y = kernel_x = _gaussian_kernel(taps, BLUR_SIGMA, light.device, light.dtype)
        else:  # kornia's gaussian_blur2d would read the sigmas back to check them: they are positive by construction
            kernel_y, kernel_x = (kornia.filters.get_gaussian_kernel1d(taps, s.unsqueeze(-1)) for s in sigma.to(light).unbind(-1))
        return kornia.filters.filter2d_separable(padded, kernel_x, kernel_y, padding="valid")
    blurred = kornia.filters.gaussian_blur2d(padded, taps, (BLUR_SIGMA, BLUR_SIGMA) if sigma is None else sigma)
    return blurred[..., radius:-radius, radius:-radius]


@device_cached
def _gaussian_kernel(taps: int, sigma: float, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """kornia's Gaussian kernel ``(1, taps)``, as ``gaussian_blur2d`` builds it at each call."""
    import kornia.filters

    return kornia.filters.get_gaussian_kernel1d(taps, torch.tensor([[sigma]], dtype=dtype, device=device))


@device_cached
def _gaussian_kernel_2d(taps: int, sigma: float, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """:func:`_gaussian_kernel` times itself, ``(1, 1, taps, taps)``: the separable blur as one convolution's weight."""
    kernel = _gaussian_kernel(taps, sigma, device, dtype)
    return (kernel.mT * kernel).reshape(1, 1, taps, taps)


def anamorphic_sigma(ratio: torch.Tensor) -> torch.Tensor:
    """Per-axis blur widths ``(sigma_y, sigma_x) = 1.69 * (2^-ratio, 2^ratio)`` as ``(B or 1, 2)``.

    Examples:
        >>> anamorphic_sigma(torch.tensor(1.0))
        tensor([[0.8450, 3.3800]])
    """
    stretch = torch.pow(2.0, ratio.reshape(-1, 1))
    return BLUR_SIGMA * torch.cat((1.0 / stretch, stretch), dim=1)


def bspline_refine(light: torch.Tensor) -> torch.Tensor:
    """The filter turning bilinear into cubic B-spline upsampling, over the mirrored frame, one axis at a time.

    Sums of shifted views (:func:`_symmetric_filter`): on CPU about 7 times faster than
    ``kornia.filters.filter2d_separable``, whose depthwise convolution oneDNN runs slowly.

    Examples:
        >>> bool(torch.allclose(bspline_refine(torch.ones(1, 1, 2, 3)), torch.ones(1, 1, 2, 3)))
        True
    """
    padded = mirror_pad(light, len(BSPLINE_AFTER_BILINEAR) // 2)
    return _symmetric_filter(_symmetric_filter(padded, BSPLINE_AFTER_BILINEAR, -1), BSPLINE_AFTER_BILINEAR, -2)


def _symmetric_filter(padded: torch.Tensor, weights, axis: int) -> torch.Tensor:
    """``w_0 x_i + sum_j w_j (x_{i-j} + x_{i+j})`` along ``axis`` for a symmetric odd-length ``weights``.

    ``padded`` carries ``radius = len(weights) // 2`` extra pixels at both ends of ``axis``; the result
    drops them. Slices with constant bounds, so a traced graph keeps working at every frame size.
    """
    radius = len(weights) // 2

    def shifted(offset: int) -> torch.Tensor:
        index = [slice(None)] * padded.dim()
        index[axis] = slice(radius + offset, (offset - radius) or None)
        return padded[tuple(index)]

    out = weights[radius] * shifted(0)
    for j in range(1, radius + 1):
        out = out + weights[radius + j] * (shifted(-j) + shifted(j))
    return out


def upsample(light: torch.Tensor, size, bicubic: bool) -> torch.Tensor:
    """Upsample light sums 2x to ``size`` keeping their total: bilinear (optionally B-spline) of block means.

    Examples:
        >>> upsample(torch.tensor([[[[4.0, 2.0]]]]), (2, 3), bicubic=False).sum()
        tensor(6.)
    """
    height, width = size
    means = light / shared_block_counts(height, width, light)
    # channels folded into the batch: PyTorch's CPU kernel is about 3 times faster on one channel
    fine = F.interpolate(means.reshape((-1, 1) + means.shape[-2:]), scale_factor=2.0, mode="bilinear", align_corners=False)
    fine = fine.reshape(means.shape[:-2] + fine.shape[-2:])[..., :height, :width]
    return bspline_refine(fine) if bicubic else fine


def nearest_upsample(values: torch.Tensor, size) -> torch.Tensor:
    """Give every pixel of a 2x2 block its block's value, cropped to ``size``.

    Examples:
        >>> nearest_upsample(torch.tensor([[[[1.0, 2.0]]]]), (1, 3))
        tensor([[[[1., 1., 2.]]]])
    """
    return F.interpolate(values, scale_factor=2.0, mode="nearest")[..., : size[0], : size[1]]


def glow_pyramid(prefiltered: torch.Tensor, depth: int, level_weight, bicubic: bool, sigma=None, active=None) -> torch.Tensor:
    """Build ``depth`` blurred levels from the prefilter and combine them back up to its resolution.

    Level ``k`` joins level ``k - 1`` as ``level + low`` (``level_weight`` None) or
    ``lerp(level, low, level_weight(k))``. With ``active`` (a 0-d tensor, see :func:`active_levels`)
    only the first ``active`` levels take part: deeper ones are built but masked out.

    Examples:
        >>> light = torch.zeros(1, 3, 8, 8); light[..., 3, 4] = 1.0
        >>> round(float(glow_pyramid(light, 2, None, bicubic=False).sum()), 4)  # each level adds the light once
        6.0
    """
    levels, light = [], prefiltered
    for _ in range(depth):
        light = pyramid_blur(sum_pool(light), sigma)
        levels.append(light)
    glow = levels[-1]
    for k in range(depth - 1, 0, -1):
        level = levels[k - 1]
        low = upsample(glow, level.shape[-2:], bicubic)
        joined = level + low if level_weight is None else torch.lerp(level, low, level_weight(k))
        glow = joined if active is None else torch.where(k < active, joined, level)
    return upsample(glow, prefiltered.shape[-2:], bicubic)
