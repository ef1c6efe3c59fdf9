"""The pyramid's blurs over the frame extended by its mirror image (half-sample symmetric, :func:`mirror_pad`): with a
symmetric kernel that operator is symmetric and its rows sum to 1, so its columns do too, and every pixel's light stays
in the frame. Unity's 9-tap binomial blur of each level (:func:`pyramid_blur`), and the anamorphic Gaussian.
"""

from __future__ import annotations

from typing import Sequence

import torch
import torch.nn.functional as F

from ..runtime import device_cached

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


def mirror_pad(light: torch.Tensor, radius, any_size: bool = False) -> torch.Tensor:
    """Extend the frame by ``radius`` pixels (a number, or ``(rows, columns)``) on every side with its mirror image
    about the edge.

    Half-sample symmetric extension (``c b a | a b c | c b a``), periodic with period ``2 · side``
    so it repeats when the frame is narrower than ``radius``. A symmetric kernel applied to it is a
    symmetric, row-stochastic operator, hence also column-stochastic: every pixel keeps all of its
    light inside the frame, and a uniform frame stays uniform. ``any_size``: index arithmetic on the tensor's own
    sizes, so a traced graph (ONNX) keeps working at every frame size (:func:`mirrored`).

    Examples:
        >>> mirror_pad(torch.tensor([[[[1.0, 2.0, 3.0]]]]), 2)[0, 0, 0]
        tensor([2., 1., 1., 2., 3., 3., 2.])
    """
    for axis, side_radius in zip((-2, -1), _radii(radius)):
        light = mirrored(light, axis, side_radius, any_size)
    return light


def _radii(radius) -> tuple:
    """``(rows, columns)`` of a radius given as one number or as both."""
    return (radius, radius) if isinstance(radius, int) else tuple(radius)


def mirrored(light: torch.Tensor, axis: int, radius: int, any_size: bool = False) -> torch.Tensor:
    """``light`` extended by ``radius`` pixels at both ends of ``axis`` (:func:`mirror_pad`): where the side is at least
    ``radius``, its edge slices flipped and joined (faster on the CPU than a gather along the last axis:
    ``benchmarks/results/cpu_forms.md``, "mirror padding of rows"); otherwise, or for a graph that serves frames of
    ``any_size`` (where the side is not known), a gather of :func:`_mirror_index`.

    Examples:
        >>> row = torch.tensor([[1.0, 2.0, 3.0]])
        >>> mirrored(row, -1, 2).tolist() == mirrored(row, -1, 2, any_size=True).tolist() == [[2.0, 1.0, 1.0, 2.0, 3.0, 3.0, 2.0]]
        True
    """
    side = light.shape[axis]
    if any_size or side < radius:
        return light.index_select(axis, _mirror_index(side, radius, light.device))
    if radius == 0:
        return light
    edges = sliced(light, axis, slice(0, radius)).flip(axis), sliced(light, axis, slice(side - radius, side)).flip(axis)
    return torch.cat((edges[0], light, edges[1]), dim=axis)


@device_cached
def _mirror_index(side: int, radius: int, device: torch.device) -> torch.Tensor:
    """The source of each pixel of a side of ``side`` pixels extended by ``radius`` (:func:`mirror_pad`)."""
    position = torch.arange(-radius, side + radius, device=device).remainder(2 * side)
    return torch.where(position < side, position, 2 * side - 1 - position)


def mirror_filter(light: torch.Tensor, weights: Sequence[float]) -> torch.Tensor:
    """``light`` filtered along both axes by the symmetric ``weights`` (numbers, normalised here) over the mirrored
    frame (:func:`mirror_pad`): keeps a uniform frame uniform and every pixel's light in the frame.

    A registered operator (``torch.ops.torchgrade.mirror_filter``) of two kernels. On the CPU, sums of shifted views
    (:func:`symmetric_filter`), 12.5 times as fast as a separable convolution, which oneDNN runs slowly
    (``benchmarks/results/cpu_forms.md``, "bloom blur"); on every other device (CUDA, ``meta``), the padding's gathers
    and two convolutions, four launches where the views take one a tap. The operator is its own adjoint (a symmetric
    kernel over the mirrored frame is a symmetric matrix), so its backward is the operator again.

    Examples:
        >>> mirror_filter(torch.tensor([[[[0.0, 4.0, 0.0]]]]), (1, 2, 1))
        tensor([[[[1., 2., 1.]]]])
    """
    return torch.ops.torchgrade.mirror_filter(light, [float(w) for w in weights])


def _mirror_filter_by_convolution(light: torch.Tensor, weights: Sequence[float]) -> torch.Tensor:
    """:func:`mirror_filter` off the CPU: the padding's gathers, then the two axes' convolutions of each plane."""
    radius, kernel = len(weights) // 2, _filter_kernel(tuple(weights), light.dtype, light.device)
    padded = mirror_pad(light, radius, any_size=True)
    planes = padded.reshape((-1, 1) + padded.shape[-2:])
    filtered = F.conv2d(F.conv2d(planes, kernel.reshape(1, 1, 1, -1)), kernel.reshape(1, 1, -1, 1))
    return filtered.reshape(light.shape)


def _mirror_filter_by_shifts(light: torch.Tensor, weights: Sequence[float]) -> torch.Tensor:
    """:func:`mirror_filter` on the CPU: sums of shifted views of the mirrored frame."""
    total = sum(weights)
    weights = tuple(w / total for w in weights)
    padded = mirror_pad(light, len(weights) // 2)
    return symmetric_filter(symmetric_filter(padded, weights, -1), weights, -2)


def _keep_weights(ctx, inputs, output) -> None:
    ctx.weights = inputs[1]


def _mirror_filter_backward(ctx, gradient: torch.Tensor):
    return torch.ops.torchgrade.mirror_filter(gradient, ctx.weights), None


def _mirror_filter_batched(info, in_dims, light: torch.Tensor, weights):
    """A batch of frames is more leading dimensions: the batched one moved first."""
    return torch.ops.torchgrade.mirror_filter(light.movedim(in_dims[0], 0), weights), 0


_OPERATORS = torch.library.Library("torchgrade", "FRAGMENT")
_OPERATORS.define("mirror_filter(Tensor light, float[] weights) -> Tensor")
_OPERATORS.impl("mirror_filter", _mirror_filter_by_convolution, "CompositeExplicitAutograd")
_OPERATORS.impl("mirror_filter", _mirror_filter_by_shifts, "CPU")
torch.library.register_fake("torchgrade::mirror_filter", lambda light, weights: torch.empty_like(light))
torch.library.register_autograd("torchgrade::mirror_filter", _mirror_filter_backward, setup_context=_keep_weights)
torch.library.register_vmap("torchgrade::mirror_filter", _mirror_filter_batched)


@device_cached
def _filter_kernel(weights: tuple, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """``weights`` normalised to sum to 1, as a 1-D tensor made once a device and dtype."""
    return torch.tensor(weights, dtype=torch.float64).div(sum(weights)).to(dtype=dtype, device=device)


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


def pyramid_blur(light: torch.Tensor, sigma=None, any_size: bool = False) -> torch.Tensor:
    """The pyramid blur over the mirrored frame (so it keeps the light): Unity's 9 taps
    (:data:`UNITY_BLUR_WEIGHTS`, :func:`unity_blur`), or with ``sigma`` ``(N or 1, 2)`` as ``(sigma_y, sigma_x)`` a
    23-tap stretched Gaussian (kornia's kernel).

    Examples:
        >>> light = torch.zeros(1, 3, 6, 6); light[..., 0, 0] = 1.0
        >>> round(float(pyramid_blur(light).sum()), 4)
        3.0
    """
    import kornia.filters  # imported at the first blur: kornia takes longer to import than torchgrade itself

    if sigma is not None:  # kornia's gaussian_blur2d would read the sigmas back to check them: they are positive
        kernel_y, kernel_x = (kornia.filters.get_gaussian_kernel1d(ANAMORPHIC_TAPS, s.unsqueeze(-1)) for s in sigma.to(light).unbind(-1))
        padded = mirror_pad(light, ANAMORPHIC_TAPS // 2, any_size)
        return kornia.filters.filter2d_separable(padded, kernel_x, kernel_y, padding="valid")
    return unity_blur(light, any_size)


def unity_blur(light: torch.Tensor, any_size: bool = False) -> torch.Tensor:
    """Unity's 9 taps (:data:`UNITY_BLUR_WEIGHTS`) over the mirrored frame, as sums of shifted views
    (:func:`mirror_filter`: on the CPU 12.5 times as fast as ``kornia.filters.filter2d_separable``,
    ``benchmarks/results/cpu_forms.md``, "bloom blur"; a compiler fuses them), or for a graph that serves frames of
    ``any_size`` (an exported model), as the operator's kernel off the CPU: a ``Conv`` node an axis of each plane, where
    the views would be a slice, a product and a sum a tap (about half the nodes of kornia's separable filter, whose
    reshapes by the channels and by the kernel's batch each take a chain of shape operations).

    Examples:
        >>> round(float(unity_blur(torch.ones(1, 1, 5, 5)).mean()), 6), round(float(unity_blur(torch.ones(1, 1, 5, 5), any_size=True).mean()), 6)
        (1.0, 1.0)
    """
    if not any_size:
        return mirror_filter(light, UNITY_BLUR_WEIGHTS)
    return _mirror_filter_by_convolution(light, UNITY_BLUR_WEIGHTS)


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
