"""Bloom: soft-knee threshold, firefly fading, a blur pyramid, additive, scattering and engine composites.

The passes follow Unity's custom-pipeline bloom (``DoBloom`` and the ``Bloom*`` shader passes):

1. **Prefilter** at half resolution (:mod:`.prefilter`): each 2x2 block's mean, then the soft-knee
   threshold (:func:`bloom_threshold`), optionally faded by a luminance-weighted average over a
   5-tap diagonal cross (``fade_fireflies``).
2. **Pyramid** (:mod:`.pyramid`): each level is the one above halved and blurred by Unity's 9 taps,
   down to ``downscale_limit`` pixels, at most ``max_iterations`` levels.
3. **Combine** from the smallest level up, bilinear (or cubic B-spline) upsampling 2x at a time, and the
   **final** pass, which samples the first level (a quarter of the frame) at the frame's resolution and
   blends it in, both as the mode's composite (:mod:`.composite`, a registry: a new mode is one blend
   function and one line of :data:`COMPOSITES`).

**Every frame size, and the edge.** Each level spans the whole frame, as a texture sampled at normalised
coordinates does: sides halve rounding up, each level pixel the exact area mean of what it covers. Taps
beyond the frame read its mirror image (for the taps one pixel out, the edge pixel itself, as Unity's
clamped sampler does). So a uniform frame blooms uniformly and a turned or mirrored frame blooms turned or
mirrored, at every size: 1x1, odd, prime, 1080p. Where the sides halve exactly down the pyramid the passes
are Unity's to rounding (``tests/bloom/test_bloom_reference.py``, against the shader passes in float64).

**Light is conserved exactly in scattering mode, borders included**: every resampling step keeps the
light (levels hold means over equal areas), the mirrored blurs keep each pixel's light in the frame, and
the prefilter reports the exact light it passed on, which scattering removes from the image. So
``sum(output) = sum(image)`` up to rounding for any threshold, knee, scatter and image size.

**Non-finite policy** (:func:`torchgrade.base.images.sanitize`, the library-wide rule): before anything
mixes pixels, NaN becomes 0 and values are bounded to ±65504, so +Inf blooms like a 65504 pixel and a
NaN pixel like a black one; no NaN or Inf reaches the output.

:class:`ConvolutionBloom` (:mod:`.convolution`) is Unreal's convolution bloom: the thresholded image
convolved with a user kernel by FFT (``torch.fft.rfft2``) over the frame extended by its mirror image.

**Precision**: float16 and bfloat16 images are computed in float32 and returned in their own dtype,
bounded to ±65504 (:func:`torchgrade.base.images.to_input_dtype`). Scene-referred values are never clamped otherwise.

Examples:
    >>> import torch
    >>> image = torch.rand(1, 3, 32, 32) * 4
    >>> out = Bloom(mode="scattering", threshold=0.5)(image)
    >>> abs(float(out.sum() / image.sum()) - 1.0) < 1e-5
    True
"""

from .composite import BLOOM_MODES, COMPOSITES, Composite
from .convolution import ConvolutionBloom, convolution_bloom, fft_convolve
from .layer import Bloom, CONTROLS, FixedDepthBloom, MAX_FRAME_SIDE, bloom, bloom_settings, bloom_with_settings
from .prefilter import bloom_threshold
from .pyramid import active_levels, pyramid_depth

__all__ = ["BLOOM_MODES", "Bloom", "COMPOSITES", "CONTROLS", "Composite", "ConvolutionBloom", "FixedDepthBloom", "MAX_FRAME_SIDE",
           "active_levels", "bloom", "bloom_settings", "bloom_threshold", "bloom_with_settings", "convolution_bloom",
           "fft_convolve", "pyramid_depth"]
