"""The bloom prefilter: Unity's soft-knee threshold, firefly fading, Karis' average and the source clamp.

The prefilter runs at half resolution (:func:`~torchgrade.bloom.pyramid.halve`: the area mean of the pixels each
half-resolution pixel covers, the 2x2 mean at even sides): each such block's source (its mean, or its Karis
average, at most ``clamp``) is thresholded, optionally faded over a 5-tap diagonal cross (Unity
``BloomPrefilterFireflies``). Besides the light entering the pyramid it returns the exact fraction of
each block's light it took, so scattering can remove from the image the light it passes on: the
threshold scales a block's source by ``r`` in [0, 1] and so takes ``r * source / mean`` of each
pixel of the block; the firefly weighted average passes on a known share of each block's
thresholded light, at most all of it. So the removed light never exceeds the image's, pixel by pixel.

**Threshold** is given in gamma space like Unity's inspector: the linear threshold is
``srgb_to_linear(threshold)`` and the knee spans ``knee * threshold_linear`` on either side.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..base.images import NEGLIGIBLE_LIGHT, check_image
from ..base.params import Param, scalar_param
from ..base.planes import channel_max
from ..color import luminance, srgb_to_linear
from ..runtime import folded, where
from .pyramid import halve

__all__ = ["SOFT_KNEE_EPSILON", "bloom_threshold", "threshold_fraction", "soft_knee", "cross_sum", "karis_mean", "prefilter"]

SOFT_KNEE_EPSILON = 1e-5
"""Unity's guard in ``w = 0.25 / (y + 0.00001)`` and ``contribution / max(brightness, 0.00001)``."""


def bloom_threshold(image: torch.Tensor, threshold: Param = 1.0, knee: Param = 0.5) -> torch.Tensor:
    """Unity's ``ApplyBloomThreshold``: the part of each pixel's light that blooms.

    ``image * r`` with ``r`` from :func:`threshold_fraction`; ``threshold`` in gamma space, ``knee``
    in [0, 1]. Pixels with brightness (max channel) below ``t - knee * t`` (``t`` linear) give 0.

    Examples:
        >>> bloom_threshold(torch.tensor([0.2, 2.0]).expand(1, 3, 1, 2), threshold=1.0, knee=0.5)[0, 0]
        tensor([[0., 1.]])
    """
    check_image(image)
    return image * threshold_fraction(image, scalar_param(threshold, image, "threshold"), scalar_param(knee, image, "knee"))


def threshold_fraction(image: torch.Tensor, threshold: Param, knee: Param) -> torch.Tensor:
    """The soft-knee fraction ``r = max(soft, b - t) / max(b, 1e-5)`` of each pixel's light, ``(..., 1, H, W)``.

    ``b`` is the max channel and ``soft = clamp(b - t + k, 0, 2k)^2 / (4 (k + 1e-5))`` with the terms of
    :func:`soft_knee`. ``r`` lies in [0, 1]. ``threshold`` and ``knee`` are numbers (the terms are then made once,
    :func:`~torchgrade.runtime.folded`) or tensors that broadcast against ``image``.

    Examples:
        >>> threshold_fraction(torch.full((1, 3, 1, 1), 4.0), 1.0, 0.5).item()
        0.75
    """
    brightness = channel_max(image)
    linear, offset, width, scale = folded(soft_knee, threshold, knee, like=brightness, host=True).unbind(-1)
    soft = torch.minimum((brightness + offset).clamp_min(0.0), width)
    soft = soft * soft * scale
    return torch.maximum(soft, brightness - linear) / brightness.clamp_min(SOFT_KNEE_EPSILON)


def soft_knee(threshold: Param, knee: Param, *, like: torch.Tensor) -> torch.Tensor:
    """Unity's threshold vector (``DoBloom``) ``(t, k - t, 2k, 0.25 / (k + 1e-5))`` on a last axis of 4, with
    ``t = srgb_to_linear(threshold)`` the linear threshold and ``k = t · knee`` half the knee's width.

    Examples:
        >>> [round(v, 4) for v in soft_knee(1.0, 0.5, like=torch.zeros(())).tolist()]
        [1.0, -0.5, 1.0, 0.5]
    """
    linear = srgb_to_linear(torch.as_tensor(threshold, dtype=like.dtype, device=like.device))
    half_width = linear * knee
    terms = linear, half_width - linear, 2.0 * half_width, 0.25 / (half_width + SOFT_KNEE_EPSILON)
    return torch.stack(torch.broadcast_tensors(*terms), dim=-1)


def cross_sum(values: torch.Tensor) -> torch.Tensor:
    """Sum over the firefly prefilter's 5 taps: the centre and its 4 diagonal neighbours, those outside the frame
    taken from the edge (clamped, as Unity's ``sampler_linear_clamp`` takes them; at one pixel from the edge that is
    also the mirror image the blurs use).

    The taps are the shader's offsets of 2 source texels, each a bilinear tap that averages a 2x2 block.
    With clamped taps the cross is a symmetric operator whose rows (and so columns) all sum to 5: a uniform frame
    stays uniform, and the light each block passes on is known exactly (:func:`prefilter`). Sums of shifted views
    of the padded tensor, the two neighbours of each row first: on the CPU faster than a 3x3 convolution
    (``kornia.filters.filter2d``), which oneDNN runs slowly (``benchmarks/results/cpu_forms.md``, "firefly cross sum").

    Examples:
        >>> cross_sum(torch.ones(1, 1, 3, 3))[0, 0]
        tensor([[5., 5., 5.],
                [5., 5., 5.],
                [5., 5., 5.]])
    """
    padded = F.pad(values, (1, 1, 1, 1), mode="replicate")
    beside = padded[..., :, :-2] + padded[..., :, 2:]
    return values + (beside[..., :-2, :] + beside[..., 2:, :])


def karis_mean(image: torch.Tensor, means: torch.Tensor, any_size: bool = False) -> torch.Tensor:
    """Karis' average of each 2x2 block: ``sum(w p) / sum(w)``, ``w = 1 / (1 + Y(p))``, capped at ``means``.

    ``Y`` is Rec.709 luminance clamped at 0 (Karis 2013, "Real Shading in Unreal Engine 4"). The
    cap binds only where a channel is brighter in a block's dim pixels than in its bright ones; it
    keeps a block from passing on more light than it has.

    Examples:
        >>> image = torch.zeros(1, 3, 2, 2); image[..., 0, 0] = 9.0
        >>> karis_mean(image, halve(image)).flatten()  # the plain mean is 2.25
        tensor([0.2903, 0.2903, 0.2903])
    """
    weight = 1.0 / (1.0 + luminance(image).clamp_min(0.0))
    return torch.minimum(halve(image * weight, any_size) / halve(weight, any_size), means)


def _source_share(source: torch.Tensor, means: torch.Tensor) -> torch.Tensor:
    """``source / mean`` per channel: the share of a block's light its source holds (exactly 1 where they are equal,
    ``x / x``).

    Blocks whose mean is below :data:`~torchgrade.base.images.NEGLIGIBLE_LIGHT` are black at any exposure: their share is 1,
    and the division is by at least that floor, so the branch not taken cannot make an infinite gradient (a mean of
    1e-40 squared underflows to 0, and 0 times that infinity is NaN).

    Examples:
        >>> _source_share(torch.tensor([0.5, 2.0, 0.0, -0.5]), torch.tensor([1.0, 2.0, 0.0, 1.0])).tolist()
        [0.5, 1.0, 1.0, -0.5]
    """
    return where(means < NEGLIGIBLE_LIGHT, 1.0, source / means.clamp_min(NEGLIGIBLE_LIGHT))


def prefilter(image: torch.Tensor, threshold, knee, fade_fireflies: bool, karis_average: bool = False, clamp=None,
              any_size: bool = False):
    """Half-resolution light entering the pyramid (means, :func:`~torchgrade.bloom.pyramid.halve`; ``any_size`` as
    its), and the fraction of each block's light it took.

    Each block's source is its mean, or its :func:`karis_mean`, then at most ``clamp``; the block
    passes on ``c = T(source)`` and so ``r * source / mean`` of its light. With fireflies (Unity
    ``BloomPrefilterFireflies``): ``p_j = sum_k w'_k c_k / W_j`` over the cross of ``j`` (:func:`cross_sum`), with
    ``w = 1 / (1 + Y(c))`` (``Y`` Rec.709 luminance, clamped at 0 so weights stay in (0, 1]) and
    ``W_j = sum_k w_k``. Every block covers the same area, and the cross is its own adjoint, so block ``k`` passes on
    ``w'_k A_k`` of its thresholded light, with ``A_k = sum_{j in cross(k)} 1 / W_j``. The weight is capped,
    ``w' = min(w, 1 / A)``, so that no block passes on more light than it has: the cap binds only for a block dimmer
    than the blocks around it (``w A = 1`` exactly in a uniform region, the frame's edges included).

    Examples:
        >>> light, fraction = prefilter(torch.full((1, 3, 4, 4), 4.0), torch.tensor(1.0), torch.tensor(0.5), True)
        >>> light.shape, round(float(light.mean()), 4), round(float(fraction.mean()), 4)
        (torch.Size([1, 3, 2, 2]), 3.0, 0.75)
    """
    means = halve(image, any_size)
    source = karis_mean(image, means, any_size) if karis_average else means
    if clamp is not None:
        source = torch.minimum(source, clamp)
    fraction = threshold_fraction(source, threshold, knee)
    share = None if source is means else _source_share(source, means)
    if not fade_fireflies:
        return source * fraction, fraction if share is None else fraction * share
    # The thresholded light c = fraction · source is not made: its luminance is fraction · Y(source) (fraction >= 0),
    # and the faded light's sum takes fraction · w' · source, the product of two planes then one frame.
    weight = 1.0 / (1.0 + (luminance(source) * fraction).clamp_min(0.0))
    total_weight = cross_sum(weight)
    reach = cross_sum(1.0 / total_weight)
    capped = torch.minimum(weight, 1.0 / reach)
    faded = cross_sum(source * (fraction * capped)) / total_weight
    taken = fraction * capped * reach
    return faded, taken if share is None else taken * share
