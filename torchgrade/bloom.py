"""Bloom: soft-knee threshold, firefly fading, a Gaussian pyramid, and additive or scattering combine.

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

**Precision**: float16 and bfloat16 images are computed in float32 and returned in their own dtype
(float16 results bounded to ±65504). Scene-referred values are never clamped otherwise.
"""

from __future__ import annotations

import math

import kornia
import torch
import torch.nn.functional as F
from torch import nn

from .color import CHANNEL, luminance, srgb_to_linear
from .core import HALF_MAX, Param, check_image, check_range, is_constant, sanitize, scalar_param

BLOOM_MODES = ("additive", "scattering")

BLUR_SIGMA = 1.69
"""Standard deviation (in level pixels) of the pyramid blur: that of Unity's 9-tap kernel (binomial
coefficients of order 12, the outer three dropped), whose variance is ``2 * 5808 / 4070 = 2.854``."""
BLUR_TAPS = 9

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


def _gaussian(light: torch.Tensor) -> torch.Tensor:
    """The pyramid blur: ``kornia.filters.gaussian_blur2d`` over the mirrored frame (so it keeps the light)."""
    radius = BLUR_TAPS // 2
    blurred = kornia.filters.gaussian_blur2d(mirror_pad(light, radius), BLUR_TAPS, (BLUR_SIGMA, BLUR_SIGMA))
    return blurred[..., radius:-radius, radius:-radius]


def _bspline_refine(light: torch.Tensor) -> torch.Tensor:
    """The filter turning bilinear into cubic B-spline upsampling, over the mirrored frame."""
    kernel = torch.tensor([BSPLINE_AFTER_BILINEAR], dtype=light.dtype, device=light.device)
    padded = mirror_pad(light, len(BSPLINE_AFTER_BILINEAR) // 2)
    return kornia.filters.filter2d_separable(padded, kernel, kernel, padding="valid")


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


def _prefilter(image: torch.Tensor, threshold, knee, fade_fireflies: bool):
    """Half-resolution light sums entering the pyramid, and the fraction of each block's light they took.

    Without fireflies: ``c = T(mean)`` per 2x2 block, fraction ``r``. With fireflies (Unity
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
    fraction = _threshold_fraction(means, threshold, knee)
    bright = means * fraction
    if not fade_fireflies:
        return bright * counts, fraction
    weight = 1.0 / (1.0 + luminance(bright).clamp_min(0.0))
    total_weight = _cross_sum(weight)
    reach = _cross_sum(counts / total_weight) / counts
    capped = torch.minimum(weight, 1.0 / reach)
    faded = _cross_sum(bright * capped) / total_weight
    return faded * counts, fraction * capped * reach


def _glow(prefiltered: torch.Tensor, depth: int, additive: bool, scatter, bicubic: bool) -> torch.Tensor:
    """Build ``depth`` blurred levels from the prefilter and combine them back up to its resolution."""
    levels, light = [], prefiltered
    for _ in range(depth):
        light = _gaussian(_sum_pool(light))
        levels.append(light)
    glow = levels[-1]
    for level in reversed(levels[:-1]):
        low = _upsample(glow, level.shape[-2:], bicubic)
        glow = level + low if additive else torch.lerp(level, low, scatter)
    return _upsample(glow, prefiltered.shape[-2:], bicubic)


def _eager() -> bool:
    """False while tracing, compiling or exporting: data-dependent shortcuts and checks are skipped."""
    return not (torch.jit.is_tracing() or torch.compiler.is_compiling() or torch.onnx.is_in_onnx_export())


def _validate(mode, threshold, knee, intensity, scatter, max_iterations, downscale_limit) -> None:
    if mode not in BLOOM_MODES:
        raise ValueError(f"mode must be one of {BLOOM_MODES}, got {mode!r}")
    for name, value, low in (("max_iterations", max_iterations, 0), ("downscale_limit", downscale_limit, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    check_range(threshold, "threshold", 0.0, math.inf)
    check_range(knee, "knee", 0.0, 1.0)
    check_range(intensity, "intensity", 0.0, math.inf)
    check_range(scatter, "scatter", 0.05, 0.95)


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
) -> torch.Tensor:
    """Bloom an HDR image ``(..., 3, H, W)``; see the module docstring for the passes and guarantees.

    Args:
        mode: ``"additive"`` (``image + intensity * glow``) or ``"scattering"`` (moves light; conserves it).
        threshold: gamma-space threshold >= 0 (Unity's inspector units); linear ``srgb_to_linear(threshold)``.
        knee: soft-knee width in [0, 1], as a fraction of the linear threshold.
        intensity: >= 0; clamped to 1 in scattering mode.
        scatter: in [0.05, 0.95] (Unity's slider); weight of the lower level in scattering mode.
        max_iterations: most pyramid levels (>= 0).
        downscale_limit: smallest level side in pixels (>= 1).
        fade_fireflies: luminance-weighted 5-tap prefilter.
        bicubic_upsampling: cubic B-spline instead of bilinear upsampling.

    Continuous parameters are numbers, 0-d tensors or per-sample ``(B,)`` tensors, differentiable.

    Identity cases return the input object untouched: ``intensity`` a plain 0, or a pyramid of depth
    0 (a side of the quarter-resolution level below ``downscale_limit``, or ``max_iterations == 0``).
    In additive mode, when no block reaches the knee, the output equals the sanitized input exactly
    (in eager mode the pyramid is then skipped).
    """
    check_image(image)
    if _eager():
        _validate(mode, threshold, knee, intensity, scatter, max_iterations, downscale_limit)
    height, width = image.shape[-2:]
    depth = pyramid_depth(height, width, max_iterations, downscale_limit)
    if depth == 0 or is_constant(intensity, 0.0):
        return image

    compute_dtype = torch.float32 if image.dtype in (torch.float16, torch.bfloat16) else image.dtype
    x = sanitize(image.to(compute_dtype)).reshape(-1, 3, height, width)
    reference = x if image.dim() == 4 else x[0]  # per-sample parameters need a (B, 3, H, W) image
    threshold, knee, intensity, scatter = (
        scalar_param(value, reference, name)
        for name, value in (("threshold", threshold), ("knee", knee), ("intensity", intensity), ("scatter", scatter))
    )

    additive = mode == "additive"
    prefiltered, fraction = _prefilter(x, threshold, knee, fade_fireflies)
    if additive and _eager() and not bool(prefiltered.any()):
        out = x
    else:
        strength = intensity if additive else intensity.clamp(max=1.0)
        glow = _glow(prefiltered, depth, additive, scatter, bicubic_upsampling)
        glow = _upsample(strength * glow, (height, width), bicubic_upsampling)
        if additive:
            out = x + glow
        else:
            kept = _nearest_upsample(1.0 - strength * fraction, (height, width))
            out = torch.addcmul(glow, x, kept)

    out = out.reshape(image.shape)
    if image.dtype == torch.float16:
        out = out.clamp(-HALF_MAX, HALF_MAX)
    return out.to(image.dtype)


_CONTINUOUS = ("threshold", "knee", "intensity", "scatter")


class Bloom(nn.Module):
    """Bloom stage; ``Bloom(...)(image)`` is :func:`bloom` with the stored settings.

    ``threshold``, ``knee``, ``intensity`` and ``scatter`` may be numbers (kept as numbers), tensors
    (registered as buffers, so they follow ``.to(device)``) or ``nn.Parameter`` (registered as
    parameters, so ``parameters()`` yields them and they can be learned). ``to_config()`` returns the
    constructor arguments as plain Python values.
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
    ) -> None:
        super().__init__()
        _validate(mode, threshold, knee, intensity, scatter, max_iterations, downscale_limit)
        self.mode = mode
        self.max_iterations = max_iterations
        self.downscale_limit = downscale_limit
        self.fade_fireflies = bool(fade_fireflies)
        self.bicubic_upsampling = bool(bicubic_upsampling)
        for name, value in zip(_CONTINUOUS, (threshold, knee, intensity, scatter)):
            if isinstance(value, nn.Parameter):
                self.register_parameter(name, value)
            elif isinstance(value, torch.Tensor):
                self.register_buffer(name, value)
            else:
                setattr(self, name, float(value))

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return bloom(
            image,
            mode=self.mode,
            threshold=self.threshold,
            knee=self.knee,
            intensity=self.intensity,
            scatter=self.scatter,
            max_iterations=self.max_iterations,
            downscale_limit=self.downscale_limit,
            fade_fireflies=self.fade_fireflies,
            bicubic_upsampling=self.bicubic_upsampling,
        )

    def to_config(self) -> dict:
        """The constructor arguments as plain values (tensors as floats or lists of floats)."""
        config = {"mode": self.mode}
        for name in _CONTINUOUS:
            value = getattr(self, name)
            config[name] = value.detach().cpu().tolist() if isinstance(value, torch.Tensor) else value
        config.update(
            max_iterations=self.max_iterations,
            downscale_limit=self.downscale_limit,
            fade_fireflies=self.fade_fireflies,
            bicubic_upsampling=self.bicubic_upsampling,
        )
        return config

    def extra_repr(self) -> str:
        return ", ".join(f"{key}={value!r}" for key, value in self.to_config().items())
