"""Colour matrices and an image's planes: a 3x3 matrix as per-channel multiply-adds, images given as their three
planes (a tuple, the form a compiled chain keeps), channel sums, maxima and minima, and a power bounded to 65504.
"""

from __future__ import annotations

import math

import torch

from ..runtime.constants import constant
from .images import HALF_MAX

__all__ = ["apply_matrix", "matrix_on_planes", "rows_on_planes", "rows_into", "each_plane", "per_channel", "channel_max", "channel_min",
           "like_image", "matrix_on", "joined", "matrix_product", "channel_sum", "bounded_pow"]

def apply_matrix(matrix: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    """``out[..., i, h, w] = sum_j matrix[..., i, j] * image[..., j, h, w]`` for (3,3) or (B,3,3) matrices.

    Three per-channel multiply-adds (a product and two ``addcmul``, :func:`matrix_on_planes`), never a matrix product:
    a 3x3 ``einsum`` runs as a batched product with an inner dimension of 3, which oneDNN and MKL block poorly
    (``benchmarks/results/cpu_forms.md``, "3x3 colour matrix, a strip"), on CUDA a matrix product is a library call
    of its own that nothing fuses (``benchmarks/bench_gpu.py``'s ``forms`` times three forms on a GPU), Inductor
    fuses these into the steps around them, and exported they are products and sums, which OpenVINO keeps in float32
    where its default bfloat16 inference runs a ``MatMul`` or an ``Einsum`` in bfloat16, coefficients and all
    (``benchmarks/results/openvino_precision.md``, "Colour matrices").

    Examples:
        >>> swap = torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        >>> apply_matrix(swap, torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1)).flatten().tolist()
        [2.0, 1.0, 3.0]
    """
    return matrix_on_planes(matrix, image.split(1, dim=-3))


def matrix_on_planes(matrix: torch.Tensor, planes) -> torch.Tensor:
    """:func:`apply_matrix` on an image given as its three planes ``(..., 1, H, W)``: ``sum_j matrix[..., :, j] planes[j]``.

    A product and two ``addcmul`` (exported as three products and two sums, ``torchgrade.onnx.symbolics``). Forms
    that already hold an image's planes pass them here instead of joining them into a frame that the matrix would only
    slice apart again (a concatenation is a pass over the frame).

    Examples:
        >>> matrix_on_planes(torch.eye(3), torch.arange(3.0).reshape(3, 1, 1, 1).unbind()).flatten().tolist()
        [0.0, 1.0, 2.0]
    """
    columns = [column[..., None, None] for column in matrix.unbind(-1)]  # (..., 3, 1, 1) each
    out = columns[0] * planes[0]
    for column, plane in zip(columns[1:], planes[1:]):
        out = torch.addcmul(out, column, plane)
    return out


def rows_on_planes(rows, planes) -> tuple:
    """A 3x3 matrix of plain numbers (``rows``, nested tuples as :func:`~torchgrade.runtime.values_of` gives) on an
    image's three planes, returned as three planes: ``out_i = sum_j rows[i][j] planes[j]``.

    The form of a chain computed on planes (:func:`~torchgrade.runtime.strips.pixelwise`): every step
    loops over the pixels once, and the numbers are written into a compiled kernel.

    Examples:
        >>> swap = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        >>> [float(p) for p in rows_on_planes(swap, (torch.tensor(1.0), torch.tensor(2.0), torch.tensor(3.0)))]
        [2.0, 1.0, 3.0]
    """
    red, green, blue = planes
    return tuple(row[0] * red + row[1] * green + row[2] * blue for row in rows)


def rows_into(rows, planes, as_planes: bool):
    """A 3x3 matrix of plain numbers (``rows``) on an image's three planes, returned as planes (``as_planes``:
    :func:`rows_on_planes`, nine products by numbers that a compiler keeps in one loop) or as an image (a product and two
    ``addcmul`` by a device constant, :func:`matrix_on_planes`: three operations eager instead of fourteen).

    Examples:
        >>> swap = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        >>> planes = torch.arange(3.0).reshape(3, 1, 1, 1).unbind()
        >>> rows_into(swap, planes, as_planes=False).flatten().tolist(), [p.item() for p in rows_into(swap, planes, as_planes=True)]
        ([1.0, 0.0, 2.0], [1.0, 0.0, 2.0])
    """
    return rows_on_planes(rows, planes) if as_planes else matrix_on_planes(constant(rows, planes[0]), planes)


def each_plane(function, x):
    """``function`` of an image, or of each of its three planes given as a tuple
    (:func:`~torchgrade.runtime.strips.pixelwise`), returned in the same form.

    Examples:
        >>> each_plane(torch.neg, (torch.tensor(1.0), torch.tensor(2.0), torch.tensor(3.0)))
        (tensor(-1.), tensor(-2.), tensor(-3.))
    """
    return tuple(function(plane) for plane in x) if isinstance(x, tuple) else function(x)


def per_channel(function, x, *coefficients):
    """``function(image, *coefficients)`` of an image and per-channel coefficients ``(..., 3, 1, 1)``; of an image given
    as its three planes (a tuple, :func:`~torchgrade.runtime.strips.pixelwise`), ``function`` of each plane
    and of its channel's coefficients ``(..., 1, 1, 1)``, returned as planes.

    Examples:
        >>> gains = torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1)
        >>> [p.item() for p in per_channel(torch.mul, (torch.ones(1, 1, 1),) * 3, gains)]
        [1.0, 2.0, 3.0]
    """
    if not isinstance(x, tuple):
        return function(x, *coefficients)
    return tuple(function(plane, *(c[..., i : i + 1, :, :] for c in coefficients)) for i, plane in enumerate(x))


def channel_max(x) -> torch.Tensor:
    """The largest channel of each pixel, ``(..., 1, H, W)``: of an image, its maximum over channels; of its three
    planes (a tuple), the maximum of the planes (no reduction: one loop a compiler fuses, a ``Max`` node exported). At a
    tie the two share the gradient differently: ``amax`` in equal parts, two ``maximum`` a half and two quarters.

    Examples:
        >>> channel_max((torch.tensor(1.0), torch.tensor(3.0), torch.tensor(2.0))).item()
        3.0
    """
    if isinstance(x, tuple):
        return torch.maximum(torch.maximum(x[0], x[1]), x[2])
    return x.amax(dim=-3, keepdim=True)


def channel_min(x) -> torch.Tensor:
    """The smallest channel of each pixel, as :func:`channel_max` takes the largest.

    Examples:
        >>> channel_min(torch.tensor([1.0, 3.0, 2.0]).reshape(3, 1, 1)).item()
        1.0
    """
    if isinstance(x, tuple):
        return torch.minimum(torch.minimum(x[0], x[1]), x[2])
    return x.amin(dim=-3, keepdim=True)


def like_image(x) -> torch.Tensor:
    """An image, or the first of its three planes (a tuple): a tensor with the image's batch, dtype and device, to make
    controls for it (:func:`color_param`, :func:`scalar_param`).

    Examples:
        >>> like_image((torch.zeros(2, 1, 4, 4),) * 3).shape
        torch.Size([2, 1, 4, 4])
    """
    return x[0] if isinstance(x, tuple) else x


def matrix_on(matrix, x):
    """:func:`apply_matrix` of a ``(3, 3)`` or ``(B, 3, 3)`` matrix on an image, or on its three planes ``(..., 1, H, W)``
    given as a tuple, returned as planes: ``out_i = sum_j matrix[..., i, j] planes[j]``. A matrix of plain numbers
    (nested tuples, :func:`~torchgrade.runtime.values_of`) is a device constant on an image and :func:`rows_on_planes`
    on planes.

    Examples:
        >>> swap = torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        >>> [p.item() for p in matrix_on(swap, torch.arange(3.0).reshape(3, 1, 1, 1).unbind())]
        [1.0, 0.0, 2.0]
        >>> matrix_on(((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)), torch.arange(3.0).reshape(3, 1, 1)).flatten().tolist()
        [1.0, 0.0, 2.0]
    """
    if not isinstance(matrix, torch.Tensor):
        return rows_on_planes(matrix, x) if isinstance(x, tuple) else apply_matrix(constant(matrix, x), x)
    if not isinstance(x, tuple):
        return apply_matrix(matrix, x)
    entries = matrix[..., None, None, None]  # a sample's entry broadcast over its plane
    return tuple(sum(entries[..., i, j, :, :, :] * plane for j, plane in enumerate(x)) for i in range(3))


def joined(x) -> torch.Tensor:
    """An image given as its three planes ``(..., 1, H, W)`` (a tuple) as one image; an image as it is.

    Examples:
        >>> joined(torch.arange(3.0).reshape(3, 1, 1, 1).unbind()).shape
        torch.Size([3, 1, 1])
    """
    return torch.stack([plane.squeeze(-3) for plane in x], dim=-3) if isinstance(x, tuple) else x


def channel_sum(image: torch.Tensor, weights) -> torch.Tensor:
    """``sum_j weights[j] * image[..., j, :, :]`` as ``(..., 1, H, W)``, for three Python-number ``weights``.

    Three passes over the planes (a product and two adds by a number): no weight tensor to make or copy, and faster on
    the CPU than a product and a channel reduction (``benchmarks/results/cpu_forms.md``, "channel sum by numbers, a
    strip"); exported as three products and two sums (a ``ReduceSum`` over channels costs onnxruntime's CPU several of
    them, ``benchmarks/results/onnx_ops.md``).

    Examples:
        >>> channel_sum(torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1), (0.5, 0.25, 0.0)).flatten().tolist()
        [1.0]
    """
    red, green, blue = image if isinstance(image, tuple) else image.split(1, dim=-3)  # or its planes, as a tuple
    return torch.add(red * weights[0], green, alpha=weights[1]).add(blue, alpha=weights[2])


def matrix_product(second: torch.Tensor, first: torch.Tensor) -> torch.Tensor:
    """``second @ first`` for (3, 3) or (B, 3, 3) colour matrices, as broadcast products summed: elementwise work
    that Inductor fuses, where a product of 3x3 matrices is a matrix-library call of its own (see :func:`apply_matrix`).

    Examples:
        >>> a, b = torch.rand(2, 3, 3), torch.rand(3, 3)
        >>> bool(torch.allclose(matrix_product(a, b), a @ b))
        True
    """
    return (second[..., :, :, None] * first[..., None, :, :]).sum(dim=-2)


_LOG2_HALF_MAX = math.log2(HALF_MAX)
_ABOVE_ONE = 1.0 + 2.0**-10
"""A base this much above the bound's root has a power above the bound for every exponent in use (down to 1e-3)."""


def bounded_pow(x: torch.Tensor, exponent) -> torch.Tensor:
    """``max(x, 0) ** exponent`` for ``exponent >= 0``, bounded to ``HALF_MAX``, with finite gradients everywhere.

    A documented control may raise an HDR value to a large power (OpenColorIO's gamma 0.01 is a
    power of 100, Unity's gamma trackball at its minimum a power of 1000): the base is clamped just above the value
    whose power is the non-finite policy's bound, ``2^(log2(65504) / exponent)``, and the power to that bound, so the
    result saturates there (with no gradient, as the bound has none) instead of overflowing to Inf, where a gradient
    would be NaN. Below the bound the value is ``x ** exponent``, down to the
    smallest normal number: a positive ``x`` below it (a denormal) is taken as it, since the slope ``e x^(e-1)`` of a
    power below 1 overflows there (a linear contrast of 0.12, a power of 0.12, gave infinite gradients at 1e-45); a
    base of 0 or less gives 0. Clamps, a power and a product: no select, in eager, compiled or exported graphs.

    Examples:
        >>> bounded_pow(torch.tensor([-1.0, 0.0, 4.0, 1e3]), 2.0).tolist()
        [0.0, 0.0, 16.0, 65504.0]
    """
    exponent = torch.as_tensor(exponent, dtype=x.dtype, device=x.device)
    beyond = torch.exp2(_LOG2_HALF_MAX / exponent.detach()) * _ABOVE_ONE  # its power is above the bound: clamped there
    powered = x.clamp(constant(torch.finfo(x.dtype).tiny, x), beyond) ** exponent
    return powered.clamp(max=HALF_MAX) * (x > 0)
