"""The pyramid's blurs over the frame extended by its mirror image (half-sample symmetric, :func:`mirror_pad`): with a
symmetric kernel that operator is symmetric and its rows sum to 1, so its columns do too, and every pixel's light stays
in the frame. Unity's 9-tap binomial blur of each level (:func:`pyramid_blur`), and the anamorphic Gaussian.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..runtime import device_cached, policy_for
from ..runtime.variants import formula

__all__ = ["UNITY_BLUR_WEIGHTS", "BLUR_TAPS", "BLUR_SIGMA", "ANAMORPHIC_TAPS", "mirror_pad", "mirror_filter", "pyramid_blur",
           "anamorphic_sigma", "mirrored", "symmetric_filter", "sliced", "unity_blur"]

UNITY_BLUR_WEIGHTS = tuple(c / 4070 for c in (66, 220, 495, 792, 924, 792, 495, 220, 66))
"""The pyramid blur per axis: the weights of Unity's ``BloomHorizontalPassFragment`` (0.01621622, 0.05405405,
0.12162162, 0.19459459, 0.22702703, ...), binomial coefficients ``C(12, k)`` for ``k = 2 .. 10`` over their sum 4070.
Its ``BloomVerticalPassFragment`` takes the same 9 taps as 5 bilinear samples."""

BLUR_TAPS = len(UNITY_BLUR_WEIGHTS)

BLUR_SIGMA = 1.69
"""Standard deviation (in level pixels) of :data:`UNITY_BLUR_WEIGHTS` (variance ``2 * 5808 / 4070 = 2.854``): the
Gaussian the anamorphic blur stretches."""

ANAMORPHIC_TAPS = 23
"""Taps of the stretched blur: radius 11 covers 3 sigma at the widest stretch (``2 * 1.69``)."""


@formula
def mirror_pad(light: torch.Tensor, radius) -> torch.Tensor:
    """Extend the frame by ``radius`` pixels (a number, or ``(rows, columns)``) on every side with its mirror image
    about the edge.

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
    for axis, side_radius in zip((-2, -1), _radii(radius)):
        light = mirrored(light, axis, side_radius)
    return light


@mirror_pad.variant("kernels")
def _mirror_pad_gathered(light: torch.Tensor, radius) -> torch.Tensor:
    """Where the device's policy takes library kernels (one launch each): one gather over the flattened plane."""
    radii, (height, width) = _radii(radius), light.shape[-2:]
    index = _mirror_plane_index(height, width, *radii, light.device)
    return light.flatten(-2).index_select(-1, index).unflatten(-1, (height + 2 * radii[0], width + 2 * radii[1]))


def _radii(radius) -> tuple:
    """``(rows, columns)`` of a radius given as one number or as both."""
    return (radius, radius) if isinstance(radius, int) else tuple(radius)


@formula
def mirrored(light: torch.Tensor, axis: int, radius: int) -> torch.Tensor:
    """``light`` extended by ``radius`` pixels at both ends of ``axis`` (:func:`mirror_pad`): where the side is at least
    ``radius`` (and sizes are not symbolic), its edge slices flipped and joined (faster on the CPU than a gather along
    the last axis: ``benchmarks/results/cpu_forms.md``, "mirror padding of rows"); otherwise a gather of :func:`_mirror_index`."""
    return light.index_select(axis, _mirror_index(light.shape[axis], radius, light.device))


@mirrored.variant("sizes", when=lambda light, axis, radius: light.shape[axis] >= radius)
def _mirrored_by_slices(light: torch.Tensor, axis: int, radius: int) -> torch.Tensor:
    """A side of at least ``radius`` pixels: its edge slices flipped and joined."""
    if radius == 0:
        return light
    side = light.shape[axis]
    edges = sliced(light, axis, slice(0, radius)).flip(axis), sliced(light, axis, slice(side - radius, side)).flip(axis)
    return torch.cat((edges[0], light, edges[1]), dim=axis)


@device_cached
def _mirror_index(side: int, radius: int, device: torch.device) -> torch.Tensor:
    """The source of each pixel of a side of ``side`` pixels extended by ``radius`` (:func:`mirror_pad`)."""
    position = torch.arange(-radius, side + radius, device=device).remainder(2 * side)
    return torch.where(position < side, position, 2 * side - 1 - position)


@device_cached
def _mirror_plane_index(height: int, width: int, row_radius: int, column_radius: int, device: torch.device) -> torch.Tensor:
    """The source of each pixel of the extended plane in the flattened ``height x width`` plane (:func:`mirror_pad`)."""
    rows, columns = _mirror_index(height, row_radius, device), _mirror_index(width, column_radius, device)
    return (rows[:, None] * width + columns[None, :]).flatten()


def mirror_filter(light: torch.Tensor, weights) -> torch.Tensor:
    """``light`` filtered along both axes by the symmetric ``weights`` (numbers, normalised here) over the mirrored
    frame: keeps a uniform frame uniform and every pixel's light in the frame.

    Sums of shifted views (:func:`symmetric_filter`): on the CPU faster than ``kornia.filters.filter2d_separable``,
    whose depthwise convolution oneDNN runs slowly (``benchmarks/results/cpu_forms.md``, "bloom blur").

    Examples:
        >>> mirror_filter(torch.tensor([[[[0.0, 4.0, 0.0]]]]), (1, 2, 1))
        tensor([[[[1., 2., 1.]]]])
    """
    total = sum(weights)
    weights = tuple(w / total for w in weights)
    padded = mirror_pad(light, len(weights) // 2)
    return symmetric_filter(symmetric_filter(padded, weights, -1), weights, -2)


def symmetric_filter(padded: torch.Tensor, weights, axis: int) -> torch.Tensor:
    """``w_0 x_i + sum_j w_j (x_{i-j} + x_{i+j})`` along ``axis`` for a symmetric odd-length ``weights``.

    ``padded`` carries ``radius = len(weights) // 2`` extra pixels at both ends of ``axis``; the result
    drops them. Slices with constant bounds, so a traced graph keeps working at every frame size.
    """
    radius = len(weights) // 2

    def shifted(offset: int) -> torch.Tensor:
        index = [slice(None)] * padded.dim()
        index[axis] = slice(radius + offset, (offset - radius) or None)
        return padded[tuple(index)]

    out = weights[radius] * shifted(0)  # a new tensor: the additions below may go into it (autograd keeps nothing of it)
    for j in range(1, radius + 1):
        out.add_(shifted(-j), alpha=weights[radius + j]).add_(shifted(j), alpha=weights[radius + j])
    return out


def pyramid_blur(light: torch.Tensor, sigma=None) -> torch.Tensor:
    """The pyramid blur over the mirrored frame (so it keeps the light): Unity's 9 taps
    (:data:`UNITY_BLUR_WEIGHTS`), or with ``sigma`` ``(N or 1, 2)`` as ``(sigma_y, sigma_x)`` a 23-tap stretched
    Gaussian (kornia's kernel).

    The 9 taps run as sums of shifted views on the CPU, and as convolutions with a kernel made once where the
    device's policy takes library kernels, or while tracing (an ONNX ``Conv``).

    Examples:
        >>> light = torch.zeros(1, 3, 6, 6); light[..., 0, 0] = 1.0
        >>> round(float(pyramid_blur(light).sum()), 4)
        3.0
    """
    import kornia.filters  # imported at the first blur: kornia takes longer to import than torchgrade itself

    if sigma is not None:  # kornia's gaussian_blur2d would read the sigmas back to check them: they are positive
        kernel_y, kernel_x = (kornia.filters.get_gaussian_kernel1d(ANAMORPHIC_TAPS, s.unsqueeze(-1)) for s in sigma.to(light).unbind(-1))
        return kornia.filters.filter2d_separable(mirror_pad(light, ANAMORPHIC_TAPS // 2), kernel_x, kernel_y, padding="valid")
    return unity_blur(light)


@formula
def unity_blur(light: torch.Tensor) -> torch.Tensor:
    """Unity's 9 taps (:data:`UNITY_BLUR_WEIGHTS`) over the mirrored frame, as kornia's separable filter (while a
    graph is recorded: an ONNX ``Conv``; kornia picks its own form for a compiler).

    Examples:
        >>> round(float(unity_blur(torch.ones(1, 1, 5, 5)).mean()), 6)
        1.0
    """
    import kornia.filters

    kernel = _blur_kernel(light.device, light.dtype)
    return kornia.filters.filter2d_separable(mirror_pad(light, BLUR_TAPS // 2), kernel, kernel, padding="valid")


@unity_blur.variant("kernels")
def _unity_blur_in_one_kernel(light: torch.Tensor) -> torch.Tensor:
    """Where the device's policy takes library kernels: small planes (up to its ``one_kernel_blur_pixels``) in one 2D
    convolution, larger ones as kornia's separable filter."""
    limit = policy_for(light.device).one_kernel_blur_pixels
    if limit is None or light.shape[-2] * light.shape[-1] > limit:
        return unity_blur.formula.reference(light)
    padded = mirror_pad(light, BLUR_TAPS // 2)
    return F.conv2d(padded.reshape((-1, 1) + padded.shape[-2:]), _blur_kernel_2d(light.device, light.dtype)).reshape(light.shape)


@unity_blur.variant("planes")
@unity_blur.variant("host")
def _unity_blur_by_shifts(light: torch.Tensor) -> torch.Tensor:
    """On the CPU, eager: sums of shifted views (:func:`mirror_filter`). Compiling too, on every device: a convolution's
    backend is chosen by its sizes (oneDNN from a batch of 16 on the CPU), and the compiled graph would keep that choice
    as a guard on the batch, compiling again for a last, smaller batch; sums of views are one fused loop for any size."""
    return mirror_filter(light, UNITY_BLUR_WEIGHTS)


@device_cached
def _blur_kernel(device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """:data:`UNITY_BLUR_WEIGHTS` as kornia's ``(1, taps)`` kernel."""
    return torch.tensor([UNITY_BLUR_WEIGHTS], dtype=dtype, device=device)


@device_cached
def _blur_kernel_2d(device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """:func:`_blur_kernel` times itself, ``(1, 1, taps, taps)``: the separable blur as one convolution's weight."""
    kernel = _blur_kernel(device, dtype)
    return (kernel.mT * kernel).reshape(1, 1, BLUR_TAPS, BLUR_TAPS)


def anamorphic_sigma(ratio: torch.Tensor) -> torch.Tensor:
    """Per-axis blur widths ``(sigma_y, sigma_x) = 1.69 * (2^-ratio, 2^ratio)`` as ``(B or 1, 2)``.

    Examples:
        >>> anamorphic_sigma(torch.tensor(1.0))
        tensor([[0.8450, 3.3800]])
    """
    stretch = torch.pow(2.0, ratio.reshape(-1, 1))
    return BLUR_SIGMA * torch.cat((1.0 / stretch, stretch), dim=1)


def sliced(light: torch.Tensor, axis: int, part: slice) -> torch.Tensor:
    """``light`` sliced by ``part`` along ``axis``."""
    index = [slice(None)] * light.dim()
    index[axis] = part
    return light[tuple(index)]
