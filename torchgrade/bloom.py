"""Bloom: soft-knee threshold, firefly fading, a Gaussian pyramid, additive, scattering and engine composites.

The passes follow Unity's custom-pipeline bloom (``DoBloom`` and the ``Bloom*`` shader passes):

1. **Prefilter** at half resolution: each 2x2 block's mean, then the soft-knee threshold
   (:func:`bloom_threshold`), optionally faded by a luminance-weighted average over a 5-tap diagonal
   cross (``fade_fireflies``).
2. **Pyramid**: each level is the previous one pooled 2x2 and blurred by a 9-tap Gaussian
   (``kornia.filters.gaussian_blur2d``), down to ``downscale_limit`` pixels, at most
   ``max_iterations`` levels.
3. **Combine** from the smallest level up, bilinear (or cubic B-spline) upsampling 2x at a time:
   ``low * 1 + high`` (additive) or ``lerp(high, low, scatter)`` (scattering).
4. **Final**: additive ``image + intensity * glow``; scattering
   ``lerp(image, glow + image - removed, min(intensity, 1))`` where ``removed`` is the light the
   prefilter took out of the image, so the pass only moves light.

**Light is conserved exactly in scattering mode, borders included.** The pyramid works on light
*sums* (each pixel holds the light of the full-resolution pixels it covers) and every resampling
step keeps the sum:

* pooling is a 2x2 sum (blocks at odd edges sum fewer pixels);
* blurs run over the frame extended by its mirror image about the edge (half-sample symmetric):
  with a symmetric kernel that operator is symmetric and its rows sum to 1, so its columns do too,
  and every pixel's light stays in the frame; clamped edges (the usual texture sampling) magnify
  edge pixels instead, and zero padding loses their light;
* bilinear 2x upsampling with ``align_corners=False`` and clamped edges gives every coarse pixel
  weights summing to the number of fine pixels it was pooled from (the crop of an odd last row or
  column included), so upsampling the block means ``m / count`` keeps the sum;
* ``removed`` is the exact light the prefilter passed on, taken from the pixels it came from: the
  threshold scales a block's mean by a fraction ``r`` in [0, 1], so it takes ``r`` of each pixel of
  the block; the firefly weighted average passes on a known share of each block's thresholded
  light (see :func:`_prefilter`), at most all of it. So ``removed <= image`` pixel by pixel and
  non-negative images stay non-negative.

So in scattering mode ``sum(output) = sum(image)`` up to rounding for any threshold, knee, scatter
and image size; in additive mode the added light is exactly
``intensity * levels * sum(prefiltered light)``.

**Non-finite policy** (:func:`torchgrade.core.sanitize`, the library-wide rule): before anything
mixes pixels, NaN becomes 0 and values are bounded to ±65504, so +Inf blooms like a 65504 pixel and a
NaN pixel like a black one; no NaN or Inf reaches the output.

**Threshold** is given in gamma space like Unity's inspector: the linear threshold is
``srgb_to_linear(threshold)`` and the knee spans ``knee * threshold_linear`` on either side.

**Engine options** (all off by default; at their defaults the output is bit-identical to the passes above):

* ``mode="energy_conserving"`` (Bevy's ``BloomCompositeMode::EnergyConserving``): each level is
  blended into the one above with Bevy's ``compute_blend_factor`` (:func:`bevy_blend_factor`:
  ``low_frequency_boost``, ``low_frequency_boost_curvature``, ``high_pass_frequency``), as
  ``lerp(level, upsampled, factor)``, and the frame becomes ``lerp(image, glow, intensity)``. Level
  ``k`` here is Bevy's mip ``k`` (the first blurred level), and the final blend (Bevy's mip 0
  factor) is ``intensity``. Unlike ``scattering`` it does not return the light the prefilter held
  back: it conserves light only when the prefilter passes all of it (``threshold=0``,
  ``fade_fireflies=False``, no ``karis_average`` or ``clamp``), and with ``low_frequency_boost=0``,
  ``high_pass_frequency=1`` it is then exactly ``scattering`` with ``scatter = intensity``.
* Godot's glow blend modes (``tonemap.glsl`` ``apply_glow``), on the additive pyramid's glow ``g``
  (``intensity`` and ``tint`` applied): ``"screen"`` ``c + g' - c g'`` with ``g' = clamp(g, 0, 1)``
  (Godot's ``white`` = 1); ``"softlight"`` ``c + g' (D(c) - c)`` with ``D(c) = ((16c - 12)c + 4)c``
  for ``c <= 0.25``, ``sqrt(c)`` above, and ``c`` unchanged above 1 (Godot blends it after tone
  mapping; here it blends where the stage runs); ``"replace"`` ``g``; ``"mix"``
  ``lerp(c, glow, intensity)`` (``intensity`` is Godot's ``glow_mix``, at most 1).
* ``karis_average`` (Karis 2013): each 2x2 block's source is the ``1 / (1 + Y)``-weighted mean of
  its pixels instead of their mean, capped per channel at the mean, so a lone hot pixel in a block
  hardly blooms. (``fade_fireflies`` weights whole blocks over a 5-tap cross instead.)
* ``clamp`` (Unity's Bloom Clamp, default 65472 there): the block source is ``min(source, clamp)``
  per channel before the threshold. The default here, 65504, is the non-finite policy's bound: no clamp.
  Both keep the light accounting exact: a block passes on ``r * source / mean`` of each channel's
  light, at most ``r``, taken from its pixels in proportion to their light.
* ``anamorphic_ratio`` in [-1, 1]: each level's Gaussian has ``sigma_x = 1.69 * 2^ratio`` and
  ``sigma_y = 1.69 * 2^-ratio`` (23 taps; positive stretches the glow horizontally, negative
  vertically; HDRP's sign is the opposite). Blurs stay mirror-padded, so scattering still conserves light.
* ``tint`` (Unity's Bloom Tint): the glow is multiplied by ``srgb_to_linear(tint)``, given
  sRGB-encoded like Unity's colour picker. Scattering conserves light only at white.
* ``dirt`` and ``dirt_intensity`` (Unity's Lens Dirt): ``output += dirt_intensity * dirt * glow``,
  with the glow at full resolution (``intensity`` and ``tint`` applied) and the dirt texture
  ``(C, h, w)`` (C = 1 or 3) resampled bilinearly to the frame (stretched). It adds light in every mode.

:class:`ConvolutionBloom` is Unreal's convolution bloom: the thresholded image convolved with a
user kernel by FFT (``torch.fft.rfft2``), zero-padded so nothing wraps around.

**Precision**: float16 and bfloat16 images are computed in float32 and returned in their own dtype
(float16 results bounded to ±65504). Scene-referred values are never clamped otherwise.
"""

from __future__ import annotations

import inspect
import math

import kornia
import torch
import torch.nn.functional as F
from torch import nn

from .color import CHANNEL, luminance, srgb_to_linear
from .core import HALF_MAX, Param, check_image, check_range, color_param, is_constant, sanitize, scalar_param

BLOOM_MODES = ("additive", "scattering", "energy_conserving", "screen", "softlight", "replace", "mix")
LERP_MODES = ("scattering", "energy_conserving", "mix")
"""Modes whose final pass is a lerp by ``intensity``, clamped to 1 there."""

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

_SOFT_KNEE_EPSILON = 1e-5  # Unity: w = 0.25 / (y + 0.00001) and contribution / max(brightness, 0.00001)


def bloom_threshold(image: torch.Tensor, threshold: Param = 1.0, knee: Param = 0.5) -> torch.Tensor:
    """Unity's ``ApplyBloomThreshold``: the part of each pixel's light that blooms.

    ``image * r`` with ``r`` from :func:`_threshold_fraction`; ``threshold`` in gamma space, ``knee``
    in [0, 1]. Pixels with brightness (max channel) below ``t - knee * t`` (``t`` linear) give 0.
    """
    check_image(image)
    return image * _threshold_fraction(image, scalar_param(threshold, image, "threshold"), scalar_param(knee, image, "knee"))


def _threshold_fraction(image: torch.Tensor, threshold: torch.Tensor, knee: torch.Tensor) -> torch.Tensor:
    """The soft-knee fraction ``r = max(soft, b - t) / max(b, 1e-5)`` of each pixel's light, ``(..., 1, H, W)``.

    ``b`` is the max channel, ``t = srgb_to_linear(threshold)``, ``k = t * knee``,
    ``soft = clamp(b - t + k, 0, 2k)^2 / (4 (k + 1e-5))`` (Unity ``DoBloom``'s threshold vector:
    x = t, y = k - t, z = 2k, w = 0.25 / (k + 1e-5)). ``r`` lies in [0, 1].
    """
    brightness = image.amax(dim=CHANNEL, keepdim=True)
    linear = srgb_to_linear(threshold)
    half_width = linear * knee
    soft = torch.minimum((brightness - linear + half_width).clamp_min(0.0), 2.0 * half_width)
    soft = soft * soft * (0.25 / (half_width + _SOFT_KNEE_EPSILON))
    return torch.maximum(soft, brightness - linear) / brightness.clamp_min(_SOFT_KNEE_EPSILON)


def pyramid_depth(height: int, width: int, max_iterations: int, downscale_limit: int) -> int:
    """Number of blurred levels below the half-resolution prefilter (Unity ``DoBloom``'s loop).

    As in Unity, level ``n`` counts while both ``floor(side / 2^(n+1))`` are at least
    ``downscale_limit``; the level tensors themselves round sizes up (:func:`_sum_pool`) so that no
    edge pixel is dropped. Depth 0 (a side under ``4 * downscale_limit`` pixels, or
    ``max_iterations = 0``) means no bloom.

    Sizes are Python ints here, as in kornia's pyramid functions, so tracing freezes the depth.
    An exporter serving every resolution from one graph has to fix the depth itself (for example
    the depth of the smallest frame it accepts). The other steps take their sizes from tensor shapes,
    except :func:`mirror_pad`'s count of reflections for levels narrower than the blur radius.
    """
    depth, h, w = 0, height // 2, width // 2
    while depth < max_iterations:
        h, w = h // 2, w // 2
        if min(h, w) < downscale_limit:
            break
        depth += 1
    return depth


def active_levels(image: torch.Tensor, max_iterations: int, downscale_limit: int) -> torch.Tensor:
    """:func:`pyramid_depth` as a 0-d tensor computed from ``image``'s runtime shape (traceable).

    Level ``n`` counts when ``floor(side / 2^(n+1)) >= downscale_limit`` for both sides, that is when
    ``min(height, width) >= downscale_limit · 2^(n+1)``.
    """
    smaller_side = torch._shape_as_tensor(image)[-2:].min()
    thresholds = downscale_limit * 2 ** torch.arange(2, max_iterations + 2)
    return (smaller_side >= thresholds).sum()


def _sum_pool(light: torch.Tensor) -> torch.Tensor:
    """2x2 sums, rounding the size up: blocks at odd edges sum the pixels they have.

    Four strided views added together: on CPU about 3 times faster than ``F.avg_pool2d``.
    """
    odd_height, odd_width = light.shape[-2] % 2, light.shape[-1] % 2
    if odd_height or odd_width or not _eager():  # F.pad copies the frame even when it adds nothing
        light = F.pad(light, (0, odd_width, 0, odd_height))
    return light[..., ::2, ::2] + light[..., 1::2, ::2] + light[..., ::2, 1::2] + light[..., 1::2, 1::2]


def _block_counts(height: int, width: int, like: torch.Tensor) -> torch.Tensor:
    """How many pixels of a ``height x width`` level each pixel of the 2x2-pooled level covers (1, 2 or 4)."""

    def per_axis(side):
        start = 2 * torch.arange(-(-side // 2), device=like.device, dtype=like.dtype)
        return (side - start).clamp(max=2.0)

    return (per_axis(height)[:, None] * per_axis(width)[None, :]).expand(1, 1, -1, -1)


def mirror_pad(light: torch.Tensor, radius: int) -> torch.Tensor:
    """Extend the frame by ``radius`` pixels on every side with its mirror image about the edge.

    Half-sample symmetric extension (``c b a | a b c | c b a``), periodic with period ``2 · side``
    so it repeats when the frame is narrower than ``radius``. A symmetric kernel applied to it is a
    symmetric, row-stochastic operator, hence also column-stochastic: every pixel keeps all of its
    light inside the frame, and a uniform frame stays uniform (clamped edges magnify edge pixels;
    zero padding loses their light). Written as index arithmetic on the tensor's own sizes, so a
    traced graph (ONNX) keeps working at every frame size.
    """
    for axis in (-2, -1):
        side = light.shape[axis]
        position = torch.arange(-radius, side + radius, device=light.device).remainder(2 * side)
        light = light.index_select(axis, torch.where(position < side, position, 2 * side - 1 - position))
    return light


def _gaussian(light: torch.Tensor, sigma=None) -> torch.Tensor:
    """The pyramid blur: ``kornia.filters.gaussian_blur2d`` over the mirrored frame (so it keeps the light).

    ``sigma`` ``(N or 1, 2)`` as ``(sigma_y, sigma_x)`` selects the 23-tap stretched blur; ``None`` the 9-tap one.
    """
    taps = BLUR_TAPS if sigma is None else ANAMORPHIC_TAPS
    sigma = (BLUR_SIGMA, BLUR_SIGMA) if sigma is None else sigma
    radius = taps // 2
    blurred = kornia.filters.gaussian_blur2d(mirror_pad(light, radius), taps, sigma)
    return blurred[..., radius:-radius, radius:-radius]


def anamorphic_sigma(ratio: torch.Tensor) -> torch.Tensor:
    """Per-axis blur widths ``(sigma_y, sigma_x) = 1.69 * (2^-ratio, 2^ratio)`` as ``(B or 1, 2)``."""
    stretch = torch.pow(2.0, ratio.reshape(-1, 1))
    return BLUR_SIGMA * torch.cat((1.0 / stretch, stretch), dim=1)


def _bspline_refine(light: torch.Tensor) -> torch.Tensor:
    """The filter turning bilinear into cubic B-spline upsampling, over the mirrored frame, one axis at a time.

    Sums of shifted views (:func:`_symmetric_filter`): on CPU about 7 times faster than
    ``kornia.filters.filter2d_separable``, whose depthwise convolution oneDNN runs slowly.
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


def _cross_sum(values: torch.Tensor) -> torch.Tensor:
    """Sum over the firefly prefilter's 5 taps, those outside the frame left out.

    The taps are the centre and the 4 diagonal neighbours at half resolution: the shader's offsets
    of 2 source texels, each a bilinear tap that averages a 2x2 block.

    Written as a sum of 5 shifted views of the zero-padded tensor: on CPU this is about 100 times
    faster than a 3x3 convolution (``kornia.filters.filter2d``), which oneDNN runs slowly.
    """
    height, width = values.shape[-2:]
    padded = F.pad(values, (1, 1, 1, 1))
    corners = (
        padded[..., :height, :width]
        + padded[..., :height, 2:]
        + padded[..., 2:, :width]
        + padded[..., 2:, 2:]
    )
    return values + corners


def _upsample(light: torch.Tensor, size, bicubic: bool) -> torch.Tensor:
    """Upsample light sums 2x to ``size`` keeping their total: bilinear (optionally B-spline) of block means."""
    height, width = size
    means = light / _block_counts(height, width, light)
    # channels folded into the batch: PyTorch's CPU kernel is about 3 times faster on one channel
    fine = F.interpolate(means.reshape((-1, 1) + means.shape[-2:]), scale_factor=2.0, mode="bilinear", align_corners=False)
    fine = fine.reshape(means.shape[:-2] + fine.shape[-2:])[..., :height, :width]
    return _bspline_refine(fine) if bicubic else fine


def _nearest_upsample(values: torch.Tensor, size) -> torch.Tensor:
    """Give every pixel of a 2x2 block its block's value."""
    return F.interpolate(values, scale_factor=2.0, mode="nearest")[..., : size[0], : size[1]]


def karis_mean(image: torch.Tensor, means: torch.Tensor) -> torch.Tensor:
    """Karis' average of each 2x2 block: ``sum(w p) / sum(w)``, ``w = 1 / (1 + Y(p))``, capped at ``means``.

    ``Y`` is Rec.709 luminance clamped at 0. The cap binds only where a channel is brighter in a
    block's dim pixels than in its bright ones; it keeps a block from passing on more light than it has.
    """
    weight = 1.0 / (1.0 + luminance(image).clamp_min(0.0))
    return torch.minimum(_sum_pool(image * weight) / _sum_pool(weight), means)


def _source_share(source: torch.Tensor, means: torch.Tensor) -> torch.Tensor:
    """``source / mean`` per channel (1 where they are equal): the share of a block's light its source holds."""
    return torch.where(source == means, torch.ones_like(means), source / torch.where(means == 0, torch.ones_like(means), means))


def _prefilter(image: torch.Tensor, threshold, knee, fade_fireflies: bool, karis_average: bool = False, clamp=None):
    """Half-resolution light sums entering the pyramid, and the fraction of each block's light they took.

    Each block's source is its mean, or its :func:`karis_mean`, then at most ``clamp``; the block
    passes on ``c = T(source)`` and so ``r * source / mean`` of its light. With fireflies (Unity
    ``BloomPrefilterFireflies``): ``p_j = sum_k w'_k c_k / W_j`` over the cross of ``j``, with
    ``w = 1 / (1 + Y(c))`` (``Y`` Rec.709 luminance, clamped at 0 so weights stay in (0, 1]) and
    ``W_j = sum_k w_k``. Block ``k`` then passes on ``w'_k A_k`` of its thresholded light, where
    ``A_k = sum_{j in cross(k)} count_j / W_j / count_k`` (the cross is its own adjoint). The weight
    is capped, ``w' = min(w, 1 / A)``, so that no block passes on more light than it has: the cap
    binds only for a dim block among much brighter ones (``w A = 1`` exactly in a uniform region),
    and keeps the light it removes from the image within that light.
    """
    counts = _block_counts(image.shape[-2], image.shape[-1], image)
    means = _sum_pool(image) / counts
    source = karis_mean(image, means) if karis_average else means
    if clamp is not None:
        source = torch.minimum(source, clamp)
    fraction = _threshold_fraction(source, threshold, knee)
    bright = source * fraction
    if source is not means:
        fraction = fraction * _source_share(source, means)
    if not fade_fireflies:
        return bright * counts, fraction
    weight = 1.0 / (1.0 + luminance(bright).clamp_min(0.0))
    total_weight = _cross_sum(weight)
    reach = _cross_sum(counts / total_weight) / counts
    capped = torch.minimum(weight, 1.0 / reach)
    faded = _cross_sum(bright * capped) / total_weight
    return faded * counts, fraction * capped * reach


def bevy_blend_factor(mip: int, max_mip: int, intensity, boost, curvature, high_pass) -> torch.Tensor:
    """Bevy's ``compute_blend_factor`` (energy-conserving): the weight of level ``mip`` blended into the one above.

    ``x = mip / max_mip``; ``boost' = (1 - (1 - x)^(1 / (1 - curvature))) * boost * (1 - intensity)``;
    ``high = 1 - clamp((x - high_pass) / high_pass, 0, 1)``; factor ``(intensity + boost') * high``.
    """
    x = mip / max_mip
    low_frequency = (1.0 - torch.pow(1.0 - x, 1.0 / (1.0 - curvature))) * boost * (1.0 - intensity)
    high_pass_weight = 1.0 - ((x - high_pass) / high_pass).clamp(0.0, 1.0)
    return (intensity + low_frequency) * high_pass_weight


def _glow(prefiltered: torch.Tensor, depth: int, level_weight, bicubic: bool, sigma=None, active=None) -> torch.Tensor:
    """Build ``depth`` blurred levels from the prefilter and combine them back up to its resolution.

    Level ``k`` joins level ``k - 1`` as ``level + low`` (``level_weight`` None) or
    ``lerp(level, low, level_weight(k))``. With ``active`` (a 0-d tensor, see :func:`active_levels`)
    only the first ``active`` levels take part: deeper ones are built but masked out.
    """
    levels, light = [], prefiltered
    for _ in range(depth):
        light = _gaussian(_sum_pool(light), sigma)
        levels.append(light)
    glow = levels[-1]
    for k in range(depth - 1, 0, -1):
        level = levels[k - 1]
        low = _upsample(glow, level.shape[-2:], bicubic)
        joined = level + low if level_weight is None else torch.lerp(level, low, level_weight(k))
        glow = joined if active is None else torch.where(k < active, joined, level)
    return _upsample(glow, prefiltered.shape[-2:], bicubic)


def screen_blend(color: torch.Tensor, glow: torch.Tensor) -> torch.Tensor:
    """Godot's screen glow (white 1): ``c + g - c g`` with ``g`` clamped to [0, 1]."""
    glow = glow.clamp(0.0, 1.0)
    return color + glow - color * glow


def softlight_blend(color: torch.Tensor, glow: torch.Tensor) -> torch.Tensor:
    """Godot's soft-light glow: ``c + g (D(c) - c)``, ``g`` in [0, 1]; ``D`` a cubic to 0.25, then ``sqrt``; ``c > 1`` kept."""
    glow = glow.clamp(0.0, 1.0)
    dark = ((16.0 * color - 12.0) * color + 4.0) * color
    target = torch.where(color <= 0.25, dark, color.clamp_min(0.25).sqrt())
    return torch.where(color > 1.0, color, color + glow * (target - color))


_BLENDS = {
    "additive": lambda image, glow, strength: glow.add_(image),
    "energy_conserving": lambda image, glow, strength: glow.addcmul_(image, 1.0 - strength),
    "mix": lambda image, glow, strength: glow.addcmul_(image, 1.0 - strength),
    "screen": lambda image, glow, strength: screen_blend(image, glow),
    "softlight": lambda image, glow, strength: softlight_blend(image, glow),
    "replace": lambda image, glow, strength: glow,
}
"""Final passes of the modes other than scattering: ``(image, intensity * glow, intensity) -> output``.

The linear ones write the output into the full-resolution ``glow`` (a fresh tensor): every new frame-sized
buffer costs page faults, and on CPU that is a large part of bloom's time.
"""


def _resampled(texture: torch.Tensor, size, like: torch.Tensor) -> torch.Tensor:
    """A ``(C, h, w)`` texture resampled bilinearly to ``size``, as ``(1, C, H, W)`` in ``like``'s dtype."""
    texture = texture.to(device=like.device, dtype=like.dtype).unsqueeze(0)
    return F.interpolate(texture, size=size, mode="bilinear", align_corners=False)


def _eager() -> bool:
    """False while tracing, compiling or exporting: data-dependent shortcuts and checks are skipped."""
    return not (torch.jit.is_tracing() or torch.compiler.is_compiling() or torch.onnx.is_in_onnx_export())


RANGES = {
    "threshold": (0.0, math.inf),
    "knee": (0.0, 1.0),
    "intensity": (0.0, math.inf),
    "scatter": (0.05, 0.95),
    "tint": (0.0, math.inf),
    "clamp": (0.0, math.inf),
    "anamorphic_ratio": (-1.0, 1.0),
    "dirt_intensity": (0.0, math.inf),
    "low_frequency_boost": (0.0, 1.0),
    "low_frequency_boost_curvature": (0.0, 0.99),
    "high_pass_frequency": (0.01, 1.0),
}
"""Allowed range of each continuous control (``tint`` per channel, sRGB-encoded)."""

OPTION_DEFAULTS = {
    "tint": (1.0, 1.0, 1.0),
    "clamp": HALF_MAX,
    "anamorphic_ratio": 0.0,
    "karis_average": False,
    "dirt": None,
    "dirt_intensity": 0.0,
    "low_frequency_boost": 0.7,
    "low_frequency_boost_curvature": 0.95,
    "high_pass_frequency": 1.0,
}
"""The engine options and their defaults (Bevy's for its three), at which Unity's bloom is unchanged."""


def _check_texture(texture, name: str, sides: str = "") -> None:
    """Raise unless ``texture`` is None or a finite floating ``(C, h, w)`` tensor with C = 1 or 3."""
    if texture is None:
        return
    if not isinstance(texture, torch.Tensor) or not texture.is_floating_point():
        raise TypeError(f"{name} must be a floating-point tensor (C, h, w), got {getattr(texture, 'dtype', type(texture).__name__)}")
    if texture.dim() != 3 or texture.shape[0] not in (1, 3) or texture.numel() == 0:
        raise ValueError(f"{name} must have shape (1 or 3, h, w), got {tuple(texture.shape)}")
    if not bool(torch.isfinite(texture).all()):
        raise ValueError(f"{name} must be finite")
    if sides == "odd" and (texture.shape[-2] % 2 == 0 or texture.shape[-1] % 2 == 0):
        raise ValueError(f"{name} must have odd sides so that its centre is a pixel, got {tuple(texture.shape)}")


def _validate(mode, max_iterations, downscale_limit, controls: dict, dirt) -> None:
    if mode not in BLOOM_MODES:
        raise ValueError(f"mode must be one of {BLOOM_MODES}, got {mode!r}")
    for name, value, low in (("max_iterations", max_iterations, 0), ("downscale_limit", downscale_limit, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    for name, value in controls.items():
        check_range(value, name, *RANGES[name])
    _check_texture(dirt, "dirt")


def _level_weight(mode: str, depth, strength: torch.Tensor, param):
    """How level ``k`` joins the one above (see :func:`_glow`): None (sum), ``scatter``, or Bevy's factor.

    ``depth`` is the number of levels taking part: an int, or a 0-d tensor under ``fixed_depth``.
    """
    if mode == "scattering":
        scatter = param("scatter")
        return lambda k: scatter
    if mode == "energy_conserving":
        boost, curvature, high_pass = (
            param(name) for name in ("low_frequency_boost", "low_frequency_boost_curvature", "high_pass_frequency")
        )
        max_mip = depth - 1 if isinstance(depth, int) else (depth - 1).clamp_min(1)
        return lambda k: bevy_blend_factor(k, max_mip, strength, boost, curvature, high_pass)
    return None


def bloom(
    image: torch.Tensor,
    mode: str = "additive",
    threshold: Param = 1.0,
    knee: Param = 0.5,
    intensity: Param = 1.0,
    scatter: Param = 0.7,
    max_iterations: int = 16,
    downscale_limit: int = 2,
    fade_fireflies: bool = True,
    bicubic_upsampling: bool = False,
    tint=(1.0, 1.0, 1.0),
    clamp: Param = HALF_MAX,
    anamorphic_ratio: Param = 0.0,
    karis_average: bool = False,
    dirt: torch.Tensor = None,
    dirt_intensity: Param = 0.0,
    low_frequency_boost: Param = 0.7,
    low_frequency_boost_curvature: Param = 0.95,
    high_pass_frequency: Param = 1.0,
    *,
    fixed_depth: int = None,
) -> torch.Tensor:
    """Bloom an HDR image ``(..., 3, H, W)``; see the module docstring for the passes and guarantees.

    Args:
        mode: ``"additive"`` (``image + intensity * glow``), ``"scattering"`` (moves light; conserves
            it), ``"energy_conserving"`` (Bevy's), or Godot's ``"screen"``, ``"softlight"``,
            ``"replace"``, ``"mix"``.
        threshold: gamma-space threshold >= 0 (Unity's inspector units); linear ``srgb_to_linear(threshold)``.
        knee: soft-knee width in [0, 1], as a fraction of the linear threshold.
        intensity: >= 0; clamped to 1 in the lerp modes (scattering, energy_conserving, mix).
        scatter: in [0.05, 0.95] (Unity's slider); weight of the lower level in scattering mode.
        max_iterations: most pyramid levels (>= 0).
        downscale_limit: smallest level side in pixels (>= 1).
        fade_fireflies: luminance-weighted 5-tap prefilter.
        bicubic_upsampling: cubic B-spline instead of bilinear upsampling.
        tint: sRGB-encoded RGB >= 0 multiplying the glow, ``(3,)`` or ``(B, 3)``.
        clamp: >= 0, upper bound of each block's bloom source per channel (Unity's Bloom Clamp).
        anamorphic_ratio: in [-1, 1]; stretches the blur horizontally (> 0) or vertically (< 0).
        karis_average: Karis' luminance-weighted 2x2 average in the prefilter.
        dirt: lens dirt texture ``(1 or 3, h, w)``, resampled to the frame.
        dirt_intensity: >= 0, weight of the dirt-modulated glow added to the output.
        low_frequency_boost, low_frequency_boost_curvature, high_pass_frequency: Bevy's controls of
            the energy-conserving level weights, in [0, 1], [0, 0.99] and [0.01, 1].

    Continuous parameters are numbers, 0-d tensors or per-sample ``(B,)`` tensors, differentiable.

    ``fixed_depth``: build that many pyramid levels whatever the frame size and mask out, with tensor
    arithmetic on the runtime shape (:func:`active_levels`), the levels this frame does not have. The
    result equals the default path for every frame whose own depth is at most ``fixed_depth``; it is
    the form a traced (ONNX) graph uses, so one graph serves every resolution.

    Identity cases return the input object untouched: ``intensity`` a plain 0 (in every mode,
    ``replace`` included), or a pyramid of depth 0 (a side of the quarter-resolution level below
    ``downscale_limit``, or ``max_iterations == 0``). In additive mode, when no block reaches the
    knee, the output equals the sanitized input exactly (in eager mode the pyramid is then
    skipped). Options at their defaults (white tint, clamp 65504, ratio 0, dirt intensity 0) are not computed.
    """
    check_image(image)
    controls = {
        "threshold": threshold, "knee": knee, "intensity": intensity, "scatter": scatter, "tint": tint, "clamp": clamp,
        "anamorphic_ratio": anamorphic_ratio, "dirt_intensity": dirt_intensity, "low_frequency_boost": low_frequency_boost,
        "low_frequency_boost_curvature": low_frequency_boost_curvature, "high_pass_frequency": high_pass_frequency,
    }
    if _eager():
        _validate(mode, max_iterations, downscale_limit, controls, dirt)
    height, width = image.shape[-2:]
    if fixed_depth is None:
        depth = active = pyramid_depth(height, width, max_iterations, downscale_limit)
    else:
        depth, active = fixed_depth, active_levels(image, min(max_iterations, fixed_depth), downscale_limit)
    if depth == 0 or is_constant(intensity, 0.0):
        return image

    compute_dtype = torch.float32 if image.dtype in (torch.float16, torch.bfloat16) else image.dtype
    x = sanitize(image.to(compute_dtype)).reshape(-1, 3, height, width)
    reference = x if image.dim() == 4 else x[0]  # per-sample parameters need a (B, 3, H, W) image

    def param(name):
        return scalar_param(controls[name], reference, name)

    bound = None if is_constant(clamp, HALF_MAX) else param("clamp")
    prefiltered, fraction = _prefilter(x, param("threshold"), param("knee"), fade_fireflies, karis_average, bound)
    if mode == "additive" and _eager() and not bool(prefiltered.any()):
        out = x
    else:
        strength = param("intensity")
        strength = strength.clamp(max=1.0) if mode in LERP_MODES else strength
        sigma = None if is_constant(anamorphic_ratio, 0.0) else anamorphic_sigma(param("anamorphic_ratio"))
        mask = None if fixed_depth is None else active
        glow = _glow(prefiltered, depth, _level_weight(mode, active, strength, param), bicubic_upsampling, sigma, mask)
        glow = _upsample(strength * glow, (height, width), bicubic_upsampling)
        if not is_constant(tint, 1.0):
            glow = glow * srgb_to_linear(color_param(tint, reference, "tint"))
        lens = None
        if dirt is not None and not is_constant(dirt_intensity, 0.0):
            lens = param("dirt_intensity") * _resampled(dirt, (height, width), x) * glow
            glow = glow.clone()  # the lens term keeps the glow for its gradient; the blend below overwrites it
        if mode == "scattering":
            kept = _nearest_upsample(1.0 - strength * fraction, (height, width))
            out = glow.addcmul_(x, kept)
        else:
            out = _BLENDS[mode](x, glow, strength)
        if lens is not None:
            out = out + lens

    if fixed_depth is not None:
        out = torch.where(active > 0, out, x)  # a frame too small for any level is not bloomed
    out = out.reshape(image.shape)
    if image.dtype == torch.float16:
        out = out.clamp(-HALF_MAX, HALF_MAX)
    return out.to(image.dtype)


def fft_convolve(light: torch.Tensor, kernel: torch.Tensor) -> torch.Tensor:
    """``light`` ``(..., H, W)`` convolved with an odd-sided ``kernel`` centred on its middle pixel, zero outside.

    Both are zero-padded to ``(H + kh - 1, W + kw - 1)`` before ``torch.fft.rfft2``, so the
    circular convolution equals the linear one (nothing wraps around); the frame is then cropped.
    """
    kh, kw = kernel.shape[-2:]
    size = (light.shape[-2] + kh - 1, light.shape[-1] + kw - 1)
    spectrum = torch.fft.rfft2(light, s=size) * torch.fft.rfft2(kernel, s=size)
    full = torch.fft.irfft2(spectrum, s=size)
    return full[..., kh // 2 : kh // 2 + light.shape[-2], kw // 2 : kw // 2 + light.shape[-1]]


def direct_convolve(light: torch.Tensor, kernel: torch.Tensor) -> torch.Tensor:
    """:func:`fft_convolve` as a direct ``conv2d`` (the kernel flipped, zero padding, one group per
    channel): the same linear convolution, in operators every ONNX runtime has."""
    kh, kw = kernel.shape[-2:]
    weight = kernel.expand(3, kh, kw).flip(-2, -1).unsqueeze(1)
    return F.conv2d(light, weight, padding=(kh // 2, kw // 2), groups=3)


def _check_kernel(kernel) -> None:
    _check_texture(kernel, "kernel", sides="odd")
    if not bool((kernel.detach().sum(dim=(-2, -1)) > 0).all()):
        raise ValueError("kernel must have a positive sum in every channel (it is normalised to sum 1)")


def convolution_bloom(
    image: torch.Tensor, kernel: torch.Tensor, threshold: Param = 1.0, knee: Param = 0.5, intensity: Param = 1.0
) -> torch.Tensor:
    """Unreal's convolution bloom: ``image + intensity * (T(image) conv k)``, by FFT (:func:`fft_convolve`).

    ``T`` is :func:`bloom_threshold` at full resolution; ``kernel`` ``(1 or 3, kh, kw)`` with odd
    sides is the glow of a point light (centred, normalised to sum 1 per channel), so a point's
    light reappears as the kernel image around it. Light beyond the frame is lost (zero padding).
    ONNX export has no FFT at opset 17, so an exported graph convolves directly
    (:func:`direct_convolve`): the same result, slower for large kernels.
    """
    check_image(image)
    controls = {"threshold": threshold, "knee": knee, "intensity": intensity}
    _check_kernel(kernel)
    for name, value in controls.items():
        check_range(value, name, *RANGES[name])
    if is_constant(intensity, 0.0):
        return image

    compute_dtype = torch.float32 if image.dtype in (torch.float16, torch.bfloat16) else image.dtype
    height, width = image.shape[-2:]
    x = sanitize(image.to(compute_dtype)).reshape(-1, 3, height, width)
    reference = x if image.dim() == 4 else x[0]
    threshold, knee, intensity = (scalar_param(value, reference, name) for name, value in controls.items())
    kernel = kernel.to(x.dtype)
    convolve = direct_convolve if torch.onnx.is_in_onnx_export() else fft_convolve
    glow = convolve(x * _threshold_fraction(x, threshold, knee), kernel / kernel.sum(dim=(-2, -1), keepdim=True))
    out = (x + intensity * glow).reshape(image.shape)
    if image.dtype == torch.float16:
        out = out.clamp(-HALF_MAX, HALF_MAX)
    return out.to(image.dtype)


def _as_texture(value):
    """A texture given as nested lists (a config) as a float tensor; tensors and None as they are."""
    return value if value is None or isinstance(value, torch.Tensor) else torch.tensor(value, dtype=torch.float32)


def _plain(value):
    """A stored control as a plain value: tensors as floats or nested lists, tuples as lists."""
    if isinstance(value, torch.Tensor):
        return value.detach().cpu().tolist()
    return list(value) if isinstance(value, tuple) else value


class _Controls(nn.Module):
    """Stores controls: ``nn.Parameter`` as parameters, tensors as buffers, numbers as floats, colours as tuples."""

    def _store(self, name: str, value) -> None:
        if isinstance(value, nn.Parameter):
            self.register_parameter(name, value)
        elif isinstance(value, torch.Tensor):
            self.register_buffer(name, value)
        elif value is None or isinstance(value, bool):
            setattr(self, name, value)
        elif isinstance(value, (int, float)):
            setattr(self, name, float(value))
        else:
            setattr(self, name, tuple(float(v) for v in value))

    def extra_repr(self) -> str:
        return ", ".join(f"{key}={value!r}" for key, value in self.to_config().items())


_ARGUMENTS = tuple(
    name for name, parameter in inspect.signature(bloom).parameters.items() if parameter.kind is not parameter.KEYWORD_ONLY
)[1:]
"""The settings :class:`Bloom` stores and passes to :func:`bloom`, in its signature's order."""
_ALWAYS_IN_CONFIG = _ARGUMENTS[: _ARGUMENTS.index("tint")]
"""Unity's settings, always in a config; the engine options appear only when not at their defaults."""


class Bloom(_Controls):
    """Bloom stage; ``Bloom(...)(image)`` is :func:`bloom` with the stored settings.

    Continuous controls may be numbers (kept as numbers), tensors (registered as buffers, so they
    follow ``.to(device)``) or ``nn.Parameter`` (registered as parameters, so ``parameters()`` yields
    them and they can be learned); ``dirt`` is a buffer. ``to_config()`` returns the constructor
    arguments as plain Python values: Unity's always, the engine options when not at their defaults.
    """

    def __init__(
        self,
        mode: str = "additive",
        threshold: Param = 1.0,
        knee: Param = 0.5,
        intensity: Param = 1.0,
        scatter: Param = 0.7,
        max_iterations: int = 16,
        downscale_limit: int = 2,
        fade_fireflies: bool = True,
        bicubic_upsampling: bool = False,
        tint=(1.0, 1.0, 1.0),
        clamp: Param = HALF_MAX,
        anamorphic_ratio: Param = 0.0,
        karis_average: bool = False,
        dirt=None,
        dirt_intensity: Param = 0.0,
        low_frequency_boost: Param = 0.7,
        low_frequency_boost_curvature: Param = 0.95,
        high_pass_frequency: Param = 1.0,
    ) -> None:
        super().__init__()
        settings = dict(locals())
        settings.update(dirt=_as_texture(dirt), fade_fireflies=bool(fade_fireflies),
                        bicubic_upsampling=bool(bicubic_upsampling), karis_average=bool(karis_average))
        _validate(mode, max_iterations, downscale_limit, {name: settings[name] for name in RANGES}, settings["dirt"])
        self.mode = mode
        self.max_iterations = max_iterations
        self.downscale_limit = downscale_limit
        for name in _ARGUMENTS[1:]:
            if name not in ("max_iterations", "downscale_limit"):
                self._store(name, settings[name])

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return bloom(image, **{name: getattr(self, name) for name in _ARGUMENTS})

    def export_form(self) -> nn.Module:
        """The fixed-depth form (:class:`FixedDepthBloom`) that one ONNX graph serves every frame size with."""
        return FixedDepthBloom(self)

    def to_config(self) -> dict:
        """The constructor arguments as plain values (tensors as floats or lists of floats)."""
        config = {name: _plain(getattr(self, name)) for name in _ALWAYS_IN_CONFIG}
        for name, default in OPTION_DEFAULTS.items():
            value = getattr(self, name)
            if isinstance(value, torch.Tensor) or value != default:
                config[name] = _plain(value)
        return config


MAX_FRAME_SIDE = 16384
"""Largest frame side an exported bloom serves exactly: the graph holds that frame's pyramid depth."""


class FixedDepthBloom(nn.Module):
    """:class:`Bloom` as a traced graph runs it: every level a frame up to :data:`MAX_FRAME_SIDE` a side
    can have is built, and the levels a frame does not have are masked out at run time
    (:func:`bloom`'s ``fixed_depth``), so one graph serves every frame size."""

    def __init__(self, stage: Bloom):
        super().__init__()
        self.stage = stage
        self.depth = pyramid_depth(MAX_FRAME_SIDE, MAX_FRAME_SIDE, stage.max_iterations, stage.downscale_limit)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        settings = {name: getattr(self.stage, name) for name in _ARGUMENTS}
        return bloom(image, **settings, fixed_depth=self.depth)


class ConvolutionBloom(_Controls):
    """Convolution bloom stage; ``ConvolutionBloom(kernel, ...)(image)`` is :func:`convolution_bloom`.

    ``kernel`` (a tensor, or nested lists from a config) is kept as a buffer, or as a parameter when
    given as ``nn.Parameter``; the other controls are stored as :class:`Bloom` stores them.
    """

    def __init__(self, kernel, threshold: Param = 1.0, knee: Param = 0.5, intensity: Param = 1.0) -> None:
        super().__init__()
        kernel = _as_texture(kernel)
        _check_kernel(kernel)
        controls = {"threshold": threshold, "knee": knee, "intensity": intensity}
        for name, value in controls.items():
            check_range(value, name, *RANGES[name])
        for name, value in {"kernel": kernel, **controls}.items():
            self._store(name, value)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return convolution_bloom(image, self.kernel, self.threshold, self.knee, self.intensity)

    def to_config(self) -> dict:
        return {name: _plain(getattr(self, name)) for name in ("kernel", "threshold", "knee", "intensity")}
