"""The bloom pyramid: level sizes, area resampling between levels and upsampling (its blurs: :mod:`torchgrade.bloom.blur`).

**Every level spans the whole frame**, as the textures of Unity's pyramid do when sampled at normalised
coordinates: a level side is half the one above, rounded up (``m = ceil(n / 2)``), and pixel ``i`` of it covers
``[i n / m, (i + 1) n / m)`` of the ``n`` pixels above. A frame and its mirror image therefore have mirrored
pyramids at every size, odd and one-pixel sides included, and a uniform frame has uniform levels.

**Light is conserved, borders included.** Levels hold means (radiance); every pixel of a level covers the same
area of the frame, so a level's light is its sum times that area, and every step keeps it:

* halving (:func:`halve`) takes exact area means: each coarse pixel the mean of the parts of the pixels it covers.
  At an even side that is the 2x2 mean; at an odd side a coarse pixel also takes the shares ``i / m`` and
  ``(m - 1 - i) / m`` of its outer neighbours;
* blurs run over the frame extended by its mirror image about the edge (half-sample symmetric, :func:`mirror_pad`):
  with a symmetric kernel that operator is symmetric and its rows sum to 1, so its columns do too, and every pixel's
  light stays in the frame; clamped edges (the usual texture sampling) magnify edge pixels instead, and zero
  padding loses their light;
* upsampling (:func:`upsample`) gives each fine pixel the coarse pixels it overlaps, by their overlap (the adjoint of
  the area mean, :func:`expand`), then smooths over the mirrored frame: ``[1, 2, 1] / 4`` for 2x, ``[1, 2, 2, 2, 1]
  / 8`` for 4x. At even sides that is exactly bilinear sampling with ``align_corners=False`` and clamped edges
  (Unity's ``sampler_linear_clamp``); at every side both steps keep a uniform frame uniform and the light sum.

Where sizes halve exactly (even sides) and double back, each step takes the forms of those sizes: four strided views
for a halving, a nearest or bilinear ``F.interpolate`` for an expansion or an upsampling, edge slices for a mirror.
A graph that serves frames of ``any_size`` (an exported model, traced at one size) takes the general forms, whose
sizes come from tensor shapes, so it keeps working at every frame size, except :func:`pyramid_depth` (Python ints, as
in kornia's pyramid functions).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..runtime import device_cached
from .blur import mirror_filter, mirrored, pyramid_blur, sliced, symmetric_filter

__all__ = ["SMOOTHING", "BSPLINE_AFTER_BILINEAR", "pyramid_depth", "active_levels", "halve", "expand", "over_blocks", "upsample", "glow_pyramid"]


SMOOTHING = {2: (1 / 4, 2 / 4, 1 / 4), 4: (1 / 8, 2 / 8, 2 / 8, 2 / 8, 1 / 8)}
"""The filter that turns :func:`expand` into bilinear upsampling, by factor: bilinear ``f``-times upsampling is
nearest upsampling followed by a box of ``f`` taps convolved with a box of 2, over ``2 f``."""

BSPLINE_AFTER_BILINEAR = {2: (1, 24, 46, 24, 1), 4: (1, 24, 48, 72, 94, 72, 48, 24, 1)}
"""Cubic B-spline upsampling is bilinear upsampling followed by this filter (per axis; weights over their sum).

At ``f``-times upsampling with half-pixel centres the B-spline weights on the zero-stuffed signal are
``B3((k + 0.5) / f - 0.5)``; for ``f = 2``, ``[1, 27, 121, 235, 235, 121, 27, 1] / 192``, which factors exactly as
bilinear ``[1, 3, 3, 1] / 4`` times ``[1, 24, 46, 24, 1] / 96``, and for ``f = 4`` as ``[1, 3, 5, 7, 7, 5, 3, 1] / 8``
times these 9 taps over 384. The B-spline (Unity's ``SampleTexture2DBicubic``) is non-negative, so unlike Keys'
bicubic (PyTorch's ``bicubic``) it never makes negative light from non-negative light, and needs no clamp."""


def pyramid_depth(height: int, width: int, max_iterations: int, downscale_limit: int) -> int:
    """Number of blurred levels below the half-resolution prefilter (Unity ``DoBloom``'s loop).

    As in Unity, level ``n`` counts while both ``floor(side / 2^(n+1))`` are at least
    ``downscale_limit``; the level tensors themselves round sizes up (:func:`halve`) so that no
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
    """:func:`pyramid_depth` as a 0-d tensor on ``image``'s device, computed from its sizes as tensors (a traced graph
    keeps them symbolic: an exported model counts the levels of each frame it is given).

    Level ``n`` counts when ``floor(side / 2^(n+1)) >= downscale_limit`` for both sides, that is when
    ``min(height, width) >= downscale_limit · 2^(n+1)``.

    Examples:
        >>> int(active_levels(torch.zeros(1, 3, 1080, 1920), 16, 2))
        8
    """
    height, width = (torch.as_tensor(side, device=image.device) for side in image.shape[-2:])
    thresholds = downscale_limit * 2 ** torch.arange(2, max_iterations + 2, device=image.device)
    return (torch.minimum(height, width) >= thresholds).sum()


def _doubles(small, large) -> bool:
    """Whether every side of ``large`` is exactly twice that of ``small``: the case bilinear resampling by 2 is."""
    return all(2 * s == big for s, big in zip(small, large))


def halve(light: torch.Tensor, any_size: bool = False) -> torch.Tensor:
    """Exact area means on sides of ``ceil(side / 2)`` pixels spanning the frame (the module's first rule).

    Pixel ``i`` of ``m = ceil(n / 2)`` is ``(m / n) (a_i x_{2i-1} + x_{2i} + b_i x_{2i+1})`` with ``a_i = i d / m``,
    ``b_i = 1 - (i + 1) d / m`` and ``d = 2 m - n`` (1 at an odd side, where the ``m`` pixels share the ``n``; 0 at an
    even one, the 2x2 mean). Even sides take the mean of four strided views (on the CPU 4.3 times as fast as
    ``F.avg_pool2d``: ``benchmarks/results/cpu_forms.md``, "bloom halving"; a compiler fuses them); other sides, and a
    graph that serves frames of ``any_size``, go a side at a time (:func:`_halve_along`).

    Examples:
        >>> halve(torch.tensor([[[[1.0, 2.0, 3.0, 4.0]]]]))
        tensor([[[[1.5000, 3.5000]]]])
        >>> halve(torch.tensor([[[[3.0, 0.0, 3.0]]]]))  # each half takes 1.5 pixels: (3 + 0.5 * 0) / 1.5
        tensor([[[[2., 2.]]]])
    """
    if any_size or light.shape[-2] % 2 or light.shape[-1] % 2:
        return _halve_along(_halve_along(light, -2), -1)
    # summed into the first sum, a fresh tensor (autograd keeps none of them): one new buffer instead of four
    return (light[..., ::2, ::2] + light[..., 1::2, ::2]).add_(light[..., ::2, 1::2]).add_(light[..., 1::2, 1::2]).mul_(0.25)


def _halve_along(light: torch.Tensor, axis: int) -> torch.Tensor:
    """:func:`halve` along one ``axis`` (-2 or -1): the side padded with a zero at both ends, then pixels ``2i - 1``,
    ``2i`` and ``2i + 1`` as three strided views (bounds fixed relative to the ends, so a traced graph serves every
    size), weighted and summed."""
    padded = F.pad(light, (1, 1) if axis == -1 else (0, 0, 1, 1))
    before, own, after = (sliced(padded, axis, slice(start, stop, 2)) for start, stop in ((0, -2), (1, -1), (2, None)))
    shape = (-1,) + (1,) * (-axis - 1)
    a, middle, b = (w.reshape(shape) for w in _halving_weight(light.shape[axis], light.dtype, light.device).unbind(-1))
    return torch.addcmul(torch.addcmul(own * middle, before, a), after, b)


@device_cached
def _halving_weight(side: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """The weights ``(m / n) (a_i, 1, b_i)`` of pixels ``2i - 1``, ``2i`` and ``2i + 1`` in pixel ``i`` of the halved
    side, ``(m, 3)`` (:func:`halve`)."""
    half = (side + 1) // 2
    odd = 2 * half - side
    i = torch.arange(half, dtype=dtype, device=device)
    before, after = i * odd / half, 1.0 - (i + 1) * odd / half
    return torch.stack((before, torch.ones_like(before), after), dim=-1) * (half / side)


def expand(values: torch.Tensor, size, any_size: bool = False) -> torch.Tensor:
    """Each pixel of the ``size`` level (sides ``n``) given the pixels of the halved level it overlaps (sides
    ``ceil(n / 2)``), weighted by overlap: the adjoint of :func:`halve`'s area mean, so ``sum`` times area is kept.

    Pixel ``2i`` takes coarse pixel ``i``; pixel ``2i + 1`` takes ``b_i`` of ``i`` and ``1 - b_i`` of ``i + 1``
    (:func:`halve`'s shares). Where the sides double exactly (unless for a graph of ``any_size``) this is
    nearest-neighbour upsampling, one ``F.interpolate``.

    Examples:
        >>> expand(torch.tensor([[[[1.0, 2.0]]]]), (1, 3))  # the middle pixel lies half in each
        tensor([[[[1.0000, 1.5000, 2.0000]]]])
    """
    if not any_size and _doubles(values.shape[-2:], size):
        return F.interpolate(values, scale_factor=2.0, mode="nearest")
    return _expand_along(_expand_along(values, -2, size[0]), -1, size[1])


def over_blocks(level: torch.Tensor, *frames: torch.Tensor, any_size: bool = False) -> tuple:
    """``frames`` (of one size) and the :func:`expand` of the halved ``level`` to their size, as tensors that broadcast
    together: where the sides double exactly (unless for a graph of ``any_size``), the frames seen as their 2x2 blocks
    ``(..., h, 2, w, 2)`` and the level as ``(..., h, 1, w, 1)``, so that the expanded level, a frame-sized buffer, is
    never written; elsewhere the frames and the expanded level. What a product of them makes has the frames' elements,
    to be reshaped to their shape.

    Examples:
        >>> level, frame = torch.tensor([[[[1.0, 2.0]]]]), torch.ones(1, 1, 2, 4)
        >>> blocks, expanded = over_blocks(level, frame)
        >>> (blocks * expanded).reshape(frame.shape).tolist() == (frame * expand(level, (2, 4))).tolist()
        True
    """
    size = frames[0].shape[-2:]
    if any_size or not _doubles(level.shape[-2:], size):
        return (*frames, expand(level, size, any_size))
    blocks = tuple(frame.unflatten(-1, (-1, 2)).unflatten(-3, (-1, 2)) for frame in frames)
    return (*blocks, level[..., :, None, :, None])


def _expand_along(values: torch.Tensor, axis: int, side: int) -> torch.Tensor:
    """:func:`expand` along one ``axis`` to ``side`` pixels: each coarse pixel twice, the second of each pair moved
    towards the next coarse pixel by its share, cropped to ``side``."""
    following = torch.cat((sliced(values, axis, slice(1, None)), sliced(values, axis, slice(-1, None))), dim=axis)
    share = _expanding_share(values.shape[axis], side, values.dtype, values.device).reshape((-1,) + (1,) * (-axis - 1))
    pairs = torch.stack((values, torch.lerp(values, following, share)), dim=axis)
    return sliced(pairs.flatten(axis - 1, axis), axis, slice(0, side))


@device_cached
def _expanding_share(half: int, side: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """The share ``(i + 1) d / m`` of coarse pixel ``i + 1`` in fine pixel ``2i + 1`` (``d = 2 m - side``: 0 at an even
    side), ``(m,)`` for the ``m = half`` coarse pixels (:func:`expand`)."""
    return torch.arange(1, half + 1, dtype=dtype, device=device) * (2 * half - side) / half


def _smooth_along(light: torch.Tensor, axis: int, weights: tuple, any_size: bool) -> torch.Tensor:
    """``light`` filtered along ``axis`` by the symmetric ``weights`` (numbers summing to 1) over the mirrored side
    (:func:`~torchgrade.bloom.blur.mirror_pad`, :func:`~torchgrade.bloom.blur.symmetric_filter`)."""
    return symmetric_filter(mirrored(light, axis, len(weights) // 2, any_size), weights, axis)


def upsample(light: torch.Tensor, sizes, bicubic: bool, any_size: bool = False) -> torch.Tensor:
    """Upsample a level through ``sizes``, each the level above the one before (one step: 2x; two: 4x), keeping a
    uniform frame uniform and the light: :func:`expand` to each size, then :data:`SMOOTHING` (bilinear) and, with
    ``bicubic``, :data:`BSPLINE_AFTER_BILINEAR` (cubic B-spline), over the mirrored frame, a side at a time.

    Where every size is exactly twice the one before (unless for a graph of ``any_size``), the same maths as one
    bilinear ``F.interpolate`` (of one channel, every leading dimension and the channels folded into its batch), then
    the B-spline's remaining smoothing.

    Examples:
        >>> upsample(torch.tensor([[[[4.0, 2.0]]]]), [(2, 4)], bicubic=False)
        tensor([[[[4.0000, 3.5000, 2.5000, 2.0000],
                  [4.0000, 3.5000, 2.5000, 2.0000]]]])
        >>> out = upsample(torch.full((1, 1, 3, 5), 2.0), [(5, 9), (9, 17)], bicubic=True)  # 4x to odd sides
        >>> out.shape, bool(torch.allclose(out, torch.tensor(2.0)))
        (torch.Size([1, 1, 9, 17]), True)
    """
    factor = 2 ** len(sizes)
    if not any_size and all(_doubles(small, large) for small, large in zip([light.shape[-2:], *sizes], sizes)):
        fine = F.interpolate(light.reshape((-1, 1) + light.shape[-2:]), scale_factor=float(factor), mode="bilinear", align_corners=False)
        fine = fine.reshape(light.shape[:-2] + fine.shape[-2:])
        return mirror_filter(fine, BSPLINE_AFTER_BILINEAR[factor]) if bicubic else fine
    smoothing = _convolved(SMOOTHING[factor], BSPLINE_AFTER_BILINEAR[factor]) if bicubic else SMOOTHING[factor]
    total = sum(smoothing)
    smoothing = tuple(w / total for w in smoothing)
    for k, axis in enumerate((-2, -1)):
        for size in sizes:
            light = _expand_along(light, axis, size[k])
        light = _smooth_along(light, axis, smoothing, any_size)
    return light


def _convolved(a, b) -> tuple:
    """The full discrete convolution of two sequences of numbers.

    Examples:
        >>> _convolved((1, 1), (1, 2, 1))
        (1, 3, 3, 1)
    """
    return tuple(sum(a[i] * b[k - i] for i in range(len(a)) if 0 <= k - i < len(b)) for k in range(len(a) + len(b) - 1))


def glow_pyramid(prefiltered: torch.Tensor, depth: int, level_weight, bicubic: bool, sigma=None, active=None,
                 any_size: bool = False) -> torch.Tensor:
    """Build ``depth`` blurred levels below the prefilter and combine them up to the first (a quarter of the frame).

    Level ``k`` joins level ``k - 1`` as ``level + low`` (``level_weight`` None) or
    ``lerp(level, low, level_weight(k))``, ``low`` the combined levels below upsampled 2x. With ``active`` (a 0-d
    tensor, see :func:`active_levels`) only the first ``active`` levels take part: deeper ones are built but masked
    out. Unity's final pass then samples the result at the frame's resolution (:func:`upsample` by 4). ``any_size``: the
    graph serves frames of any size (an exported model: the general forms, :mod:`~torchgrade.bloom.pyramid`).

    Examples:
        >>> light = torch.zeros(1, 3, 8, 8); light[..., 3, 4] = 1.0
        >>> glow = glow_pyramid(light, 2, None, bicubic=False)   # each level holds the light once, at 1/4 the area
        >>> glow.shape[-2:], round(float(glow.sum() * 4), 4)
        (torch.Size([4, 4]), 6.0)
    """
    levels, light = [], prefiltered
    for _ in range(depth):
        light = pyramid_blur(halve(light, any_size), sigma, any_size)
        levels.append(light)
    glow = levels[-1]
    for k in range(depth - 1, 0, -1):
        level = levels[k - 1]
        low = upsample(glow, [level.shape[-2:]], bicubic, any_size)
        joined = level + low if level_weight is None else torch.lerp(level, low, level_weight(k))
        glow = joined if active is None else torch.where(k < active, joined, level)
    return glow
