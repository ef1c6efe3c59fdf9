"""Bloom: soft-knee threshold, firefly fading, a Gaussian pyramid, additive, scattering and engine composites.

The passes follow Unity's custom-pipeline bloom (``DoBloom`` and the ``Bloom*`` shader passes):

1. **Prefilter** at half resolution (:mod:`.prefilter`): each 2x2 block's mean, then the soft-knee
   threshold (:func:`bloom_threshold`), optionally faded by a luminance-weighted average over a
   5-tap diagonal cross (``fade_fireflies``).
2. **Pyramid** (:mod:`.pyramid`): each level is the previous one pooled 2x2 and blurred by a 9-tap
   Gaussian (``kornia.filters.gaussian_blur2d``), down to ``downscale_limit`` pixels, at most
   ``max_iterations`` levels.
3. **Combine** from the smallest level up, bilinear (or cubic B-spline) upsampling 2x at a time, and
   the **final** blend, both as the mode's composite (:mod:`.composite`, a registry: a new mode is
   one blend function and one line of :data:`COMPOSITES`).

**Light is conserved exactly in scattering mode, borders included**: the pyramid keeps light sums
through every resampling step, and the prefilter reports the exact light it passed on, which
scattering removes from the image. So ``sum(output) = sum(image)`` up to rounding for any threshold,
knee, scatter and image size; in additive mode the added light is exactly
``intensity * levels * sum(prefiltered light)``.

**Non-finite policy** (:func:`torchgrade.core.sanitize`, the library-wide rule): before anything
mixes pixels, NaN becomes 0 and values are bounded to ±65504, so +Inf blooms like a 65504 pixel and a
NaN pixel like a black one; no NaN or Inf reaches the output.

:class:`ConvolutionBloom` (:mod:`.convolution`) is Unreal's convolution bloom: the thresholded image
convolved with a user kernel by FFT (``torch.fft.rfft2``), zero-padded so nothing wraps around.

**Precision**: float16 and bfloat16 images are computed in float32 and returned in their own dtype,
bounded to ±65504 (:func:`torchgrade.core.to_input_dtype`). Scene-referred values are never clamped otherwise.

Examples:
    >>> import torch
    >>> image = torch.rand(1, 3, 32, 32) * 4
    >>> out = Bloom(mode="scattering", threshold=0.5)(image)
    >>> abs(float(out.sum() / image.sum()) - 1.0) < 1e-5
    True
"""

from .composite import (
    BLOOM_MODES, COMPOSITES, LERP_MODES, Composite, additive_blend, bevy_blend_factor, bevy_weight, lerp_blend,
    replace_blend, scatter_weight, scattering_blend, screen_blend, softlight_blend,
)
from .convolution import ConvolutionBloom, DirectConvolutionBloom, check_kernel, convolution_bloom, direct_convolve, fft_convolve
from .layer import (
    CONTROLS, MAX_FRAME_SIDE, OPTION_DEFAULTS, UNITY_SETTINGS, Bloom, FixedDepthBloom, bloom, bloom_settings, bloom_with_settings, check_settings,
)
from .prefilter import SOFT_KNEE_EPSILON, bloom_threshold, cross_sum, karis_mean, prefilter, threshold_fraction
from .pyramid import (
    ANAMORPHIC_TAPS, BLUR_SIGMA, BLUR_TAPS, BSPLINE_AFTER_BILINEAR, active_levels, anamorphic_sigma, block_counts,
    bspline_refine, glow_pyramid, mirror_pad, nearest_upsample, pyramid_blur, pyramid_depth, sum_pool, upsample,
)
from .texture import as_texture, check_texture, resampled

__all__ = [
    # the stages and functionals
    "Bloom", "ConvolutionBloom", "bloom", "bloom_threshold", "convolution_bloom", "fft_convolve", "direct_convolve",
    "FixedDepthBloom", "DirectConvolutionBloom", "MAX_FRAME_SIDE", "CONTROLS", "UNITY_SETTINGS", "OPTION_DEFAULTS",
    "check_settings", "check_kernel", "bloom_settings", "bloom_with_settings",
    # composites
    "Composite", "COMPOSITES", "BLOOM_MODES", "LERP_MODES", "bevy_blend_factor", "scatter_weight", "bevy_weight",
    "additive_blend", "scattering_blend", "lerp_blend", "screen_blend", "softlight_blend", "replace_blend",
    # prefilter
    "SOFT_KNEE_EPSILON", "threshold_fraction", "cross_sum", "karis_mean", "prefilter",
    # pyramid
    "BLUR_SIGMA", "BLUR_TAPS", "ANAMORPHIC_TAPS", "BSPLINE_AFTER_BILINEAR", "pyramid_depth", "active_levels", "sum_pool",
    "block_counts", "mirror_pad", "pyramid_blur", "anamorphic_sigma", "bspline_refine", "upsample", "nearest_upsample",
    "glow_pyramid",
    # textures
    "as_texture", "check_texture", "resampled",
]
