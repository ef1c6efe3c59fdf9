"""Shared conventions: image validation, parameter broadcasting and the non-finite input policy.

Every public module of torchgrade goes through these helpers, so the rules are stated once:

* Images are float tensors ``(..., 3, H, W)`` (a stage also takes ``(..., 4, H, W)``, its alpha passed through:
  :func:`with_alpha`); anything else is a ``TypeError`` (dtype) or a ``ValueError`` (shape), with a message naming
  the problem and the caller's shape.
* Parameters may be a Python number, a 0-d tensor, a per-sample tensor ``(B,)`` (colours ``(B, 3)``,
  matrices ``(B, 3, 3)``) or an ``nn.Parameter``; they are cast to the image's dtype and device and
  shaped to broadcast against ``(B, 3, H, W)``.
* **Non-finite policy** (:func:`sanitize`): NaN becomes 0 and every value is bounded to
  ``[-HALF_MAX, HALF_MAX]`` (±65504, the range of the half-float HDR buffers that engines render
  to), so ±Inf becomes ±65504. Stages that mix pixels (bloom, metering) or raise values to powers
  apply it first, so one bad pixel never spreads and intermediate sums never overflow in float32.
  Scene-referred values inside that range are never clamped.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import numbers
import warnings
from typing import Union

import torch

from ..runtime.constants import constant, is_plain_number, where
from ..runtime.policy import policy_for
from ..runtime.recording import is_differentiated, is_exporting, is_tracing, untracked
from ..runtime.strips import named_as

Param = Union[float, int, torch.Tensor]

__all__ = [
    "Param",
    "HALF_MAX",
    "NEGLIGIBLE_LIGHT",
    "check_image",
    "with_alpha",
    "warn_if_eight_bit",
    "check_on_cpu",
    "sanitize",
    "nan_free",
    "scalar_param",
    "is_plain_number",
    "color_param",
    "matrix_param",
    "apply_matrix",
    "matrix_on_planes",
    "rows_on_planes",
    "each_plane",
    "per_channel",
    "channel_max",
    "channel_min",
    "like_image",
    "matrix_on",
    "joined",
    "matrix_product",
    "channel_sum",
    "check_range",
    "check_choice",
    "is_constant",
    "readable",
    "is_tracing",
    "untracked",
    "working_dtype",
    "to_input_dtype",
    "full_precision",
    "one_thread",
    "bounded_pow",
]

HALF_MAX = 65504.0
"""Largest finite half-float value: the bound of the non-finite policy."""

NEGLIGIBLE_LIGHT = 1e-10
"""Light below this is black at any exposure a display shows (2^-33 of white). Divisions by a quantity of light
(a hue's chroma, a block's mean) take such values as black, or divide by at least this: squared, a float32
denormal underflows to 0, and the division's gradient to infinity."""


def check_image(image: torch.Tensor, name: str = "image", alpha: bool = False) -> None:
    """Raise a clear error unless ``image`` is a non-empty floating tensor shaped ``(..., 3, H, W)`` (with ``alpha``, also
    ``(..., 4, H, W)``: colour and alpha).

    Examples:
        >>> check_image(torch.zeros(1, 4, 2, 2))
        Traceback (most recent call last):
        ...
        ValueError: image must have shape (..., 3, H, W) with 3 colour channels, got (1, 4, 2, 2)
    """
    if not isinstance(image, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(image).__name__}")
    if not image.is_floating_point():
        raise TypeError(
            f"{name} must be a floating-point tensor (float16, bfloat16, float32 or float64), got {image.dtype}; "
            "an 8-bit image holds sRGB codes: tg.color.srgb_to_linear(image.float() / 255) gives the linear light a "
            'stage takes, and RandomPostFX(input_space="srgb") grades image.float() / 255 as it is'
        )
    channels = (3, 4) if alpha else (3,)
    if image.dim() < 3 or image.shape[-3] not in channels:
        with_alpha = ", or (..., 4, H, W) with alpha" if alpha else ""
        raise ValueError(f"{name} must have shape (..., 3, H, W) with 3 colour channels{with_alpha}, got {tuple(image.shape)}")
    if image.numel() == 0:
        raise ValueError(f"{name} is empty: shape {tuple(image.shape)}")


def with_alpha(function, image: torch.Tensor, *args, **kwargs) -> torch.Tensor:
    """``function(image, *args, **kwargs)`` for a checked ``(..., 3, H, W)`` image; for ``(..., 4, H, W)``, ``function`` of the
    colour channels with the fourth (alpha) appended unchanged, as OpenColorIO and compositors grade RGBA. An error
    naming the colour's shape names the caller's.

    Examples:
        >>> rgba = torch.tensor([1.0, 2.0, 3.0, 0.5]).reshape(1, 4, 1, 1)
        >>> with_alpha(lambda x: x * 2, rgba).flatten().tolist()
        [2.0, 4.0, 6.0, 0.5]
    """
    check_image(image, alpha=True)
    if image.shape[-3] == 3:
        return function(image, *args, **kwargs)
    colour, alpha = image.split((3, 1), dim=-3)
    with named_as(colour.shape, image.shape):
        return torch.cat((function(colour, *args, **kwargs), alpha), dim=-3)


EIGHT_BIT_ROWS = 8
"""Rows :func:`warn_if_eight_bit` reads at most (at least half as many), evenly spaced, of the colour of the first image
of a batch: whole rows, read in order. In the cinematic look at 1920x1080 (CPU time, one thread) the check took 0.24 ms
a stage call, 0.3 % of the frame; 64x64 values spread over the frame took 0.39 ms (a cache line fetched per value)."""


EIGHT_BIT_LEVELS = 16
"""Different whole numbers from which a sample reads as an 8-bit picture: a photograph's 8 rows hold far more (the
sample pictures of the suite: every one above 60), a synthetic HDR frame of whole-number lamps on black a handful."""


def warn_if_eight_bit(image: torch.Tensor) -> None:
    """Warn when a linear ``image`` looks like 0..255 data: a sample of it holds whole numbers only, at least
    :data:`EIGHT_BIT_LEVELS` different ones, none negative, the largest in (1, 255]. Such floats taken as light come out
    nearly white; an HDR frame holds fractions, and a frame of a few whole levels (a test pattern of lamps of 8 and
    60 on black) is no 8-bit picture. Only where the device's policy reads values (the CPU, :func:`readable`): on a
    GPU the read would wait for the device at every frame.

    Examples:
        >>> import warnings
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     warn_if_eight_bit(torch.arange(48.0).reshape(3, 4, 4) * 5)
        >>> "divide by 255" in str(caught[0].message)
        True
    """
    if not readable(image):
        return
    first = image.detach()[(0,) * (image.dim() - 3)][:3]  # colour, without an alpha
    sample = first[:, :: max(1, first.shape[-2] // EIGHT_BIT_ROWS)]
    with one_thread():  # tens of thousands of values: a parallel region's barrier would cost more on a loaded machine
        low, high = torch.stack(sample.aminmax()).tolist()  # one read
        eight_bit = (0.0 <= low < high and 1.0 < high <= 255.0 and torch.equal(sample, sample.round())
                     and sample.unique().numel() >= EIGHT_BIT_LEVELS)  # counted only where the rest holds: almost never
    if eight_bit:
        warnings.warn(
            f"the image looks like 0..255 data (whole numbers up to {high:g}), but stages take linear light: divide "
            "by 255, and decode sRGB-encoded pictures (PNG, JPEG) with tg.color.srgb_to_linear or grade them with "
            'RandomPostFX(input_space="srgb")', UserWarning, stacklevel=3)


_NAN_FREE = contextvars.ContextVar("nan_free", default=None)


def sanitize(image: torch.Tensor) -> torch.Tensor:
    """Apply the non-finite policy: NaN -> 0, values bounded to [-65504, 65504] (so ±Inf -> ±65504).

    ``clamp`` keeps NaN, so the clamped copy is then fixed in place: one new frame instead of two. Inside
    :func:`nan_free` for this very tensor only the bound is applied.

    Examples:
        >>> sanitize(torch.tensor([float('nan'), float('inf'), -1.0])).tolist()
        [0.0, 65504.0, -1.0]
    """
    bounded = image.clamp(-HALF_MAX, HALF_MAX)
    exporting = is_exporting()
    if (exporting or not is_tracing()) and _NAN_FREE.get() is image:  # a compiler would break its graph to read it
        return bounded
    if not exporting:
        return bounded.nan_to_num_(nan=0.0)
    # NaN is found on the input itself: OpenVINO's Clip turns NaN into its lower bound (the clamped copy's NaN came
    # out -65504 there); and nan_to_num would export a second Clip, to the dtype's range, a copy of the frame.
    return torch.where(torch.isnan(image), 0.0, bounded)


@contextlib.contextmanager
def nan_free(image: torch.Tensor):
    """Within the block, :func:`sanitize` of ``image`` (this tensor object) only bounds it: the caller knows that
    ``image`` holds no NaN (the output of a stage, which never makes one: ``tests/library/test_extremes.py``), so
    the NaN pass over the frame (a kernel, or ``IsNaN`` and ``Where`` in an exported graph) is left out.

    Examples:
        >>> x = torch.tensor([float('nan'), 1e6])
        >>> sanitize(x).tolist()
        [0.0, 65504.0]
        >>> with nan_free(x):
        ...     sanitize(x).tolist()  # trusted: only bounded
        [nan, 65504.0]

    While ``torch.compile`` traces, nothing: a compiled :func:`sanitize` does not look (Dynamo cannot trace a context
    variable, and the compiler fuses the NaN pass into its neighbours).
    """
    if torch.compiler.is_compiling():
        yield
        return
    token = _NAN_FREE.set(image)
    try:
        yield
    finally:
        _NAN_FREE.reset(token)


def _as_tensor(value: Param, image: torch.Tensor, name: str) -> torch.Tensor:
    if isinstance(value, torch.Tensor):
        if value.is_complex() or not (value.is_floating_point() or value.dtype in _INT_DTYPES):
            raise TypeError(f"parameter {name!r} must be a real number tensor, got {value.dtype}")
        return value.to(device=image.device, dtype=image.dtype)
    if not is_plain_number(value):
        raise TypeError(f"parameter {name!r} must be a number or a tensor, got {type(value).__name__}")
    return constant(float(value), image)


_INT_DTYPES = (torch.int8, torch.int16, torch.int32, torch.int64, torch.uint8)


def _per_sample(t: torch.Tensor, image: torch.Tensor, name: str, trailing: int) -> torch.Tensor:
    """Shape a per-sample tensor ``(B, *k)`` to ``(B, *k, 1, 1)`` after checking B against the image."""
    batch = t.shape[0]
    if image.dim() != 4 or image.shape[0] != batch:
        raise ValueError(
            f"parameter {name!r} has {batch} per-sample values but the image has shape {tuple(image.shape)}; "
            f"per-sample parameters need a (B, 3, H, W) image with B = {batch}"
        )
    return t.reshape(t.shape + (1,) * (image.dim() - 1 - trailing))


def scalar_param(value: Param, image: torch.Tensor, name: str) -> torch.Tensor:
    """A scalar control as a tensor that broadcasts against ``image``: 0-d, or ``(B, 1, 1, 1)``.

    Examples:
        >>> image = torch.zeros(2, 3, 4, 4)
        >>> scalar_param(0.5, image, 'gain').shape, scalar_param(torch.tensor([1.0, 2.0]), image, 'gain').shape
        (torch.Size([]), torch.Size([2, 1, 1, 1]))
    """
    t = _as_tensor(value, image, name)
    if t.dim() == 0:
        return t
    if t.dim() == 1:
        return _per_sample(t, image, name, trailing=0)
    raise ValueError(f"parameter {name!r} must be a number, a 0-d tensor or a (B,) tensor, got shape {tuple(t.shape)}")


def color_param(value, image: torch.Tensor, name: str) -> torch.Tensor:
    """An RGB control as ``(3, 1, 1)`` or per sample ``(B, 3, 1, 1)``; accepts a 3-sequence or tensor, or a plain
    number ``v`` for the grey ``(v, v, v)``.

    Examples:
        >>> color_param((1.0, 0.5, 0.25), torch.zeros(1, 3, 2, 2), 'tint').shape
        torch.Size([3, 1, 1])
        >>> color_param(0.5, torch.zeros(1, 3, 2, 2), 'tint').flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    if is_plain_number(value):
        value = (value,) * 3
    t = _as_tensor(value, image, name) if isinstance(value, torch.Tensor) else _sequence(value, image, name)
    if t.shape == (3,):
        return t.reshape(3, 1, 1)
    if t.dim() == 2 and t.shape[1] == 3:
        return _per_sample(t, image, name, trailing=1)
    raise ValueError(f"parameter {name!r} must be an RGB triple (3,) or per-sample (B, 3), got shape {tuple(t.shape)}")


def matrix_param(value, image: torch.Tensor, name: str) -> torch.Tensor:
    """A 3x3 colour matrix as ``(3, 3)`` or per sample ``(B, 3, 3)``.

    Examples:
        >>> matrix_param(((1, 0, 0), (0, 1, 0), (0, 0, 1)), torch.zeros(1, 3, 2, 2), 'mixer').shape
        torch.Size([3, 3])
    """
    t = _as_tensor(value, image, name) if isinstance(value, torch.Tensor) else _sequence(value, image, name)
    if t.shape == (3, 3) or (t.dim() == 3 and t.shape[1:] == (3, 3)):
        if t.dim() == 3:
            _per_sample(t, image, name, trailing=2)
        return t
    raise ValueError(f"parameter {name!r} must be a 3x3 matrix or per-sample (B, 3, 3), got shape {tuple(t.shape)}")


def _sequence(value, image: torch.Tensor, name: str) -> torch.Tensor:
    """A colour or matrix given as (nested) numbers, as a tensor on ``image``'s device, made there once per value."""
    try:
        return constant(_nested_floats(value), image)
    except (TypeError, ValueError, RuntimeError) as error:
        raise TypeError(f"parameter {name!r} must be numbers or a tensor: {error}") from None


def _nested_floats(value):
    """A number or nested sequence of numbers as nested tuples of floats (hashable: a key of the constants' cache)."""
    if isinstance(value, (list, tuple)):
        return tuple(_nested_floats(item) for item in value)
    if not is_plain_number(value):
        raise TypeError(f"expected a number, got {type(value).__name__}")
    return float(value)


def apply_matrix(matrix: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    """``out[..., i, h, w] = sum_j matrix[..., i, j] * image[..., j, h, w]`` for (3,3) or (B,3,3) matrices.

    Three per-channel multiply-adds (a product and two ``addcmul``), never a matrix product: a 3x3 ``einsum``
    runs as a batched product with an inner dimension of 3, which oneDNN and MKL block poorly (2x the time of
    these passes on a CPU strip of 2^17 pixels), cuBLAS runs as ``gemv`` calls that nothing fuses (2.59 of a
    compiled look's 4.47 ms on an H200, ``../shared/measurements/gpu-h200``), and Inductor fuses these into the
    steps around them. Computed in place where nothing records (:func:`untracked`).

    Examples:
        >>> swap = torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        >>> apply_matrix(swap, torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1)).flatten().tolist()
        [2.0, 1.0, 3.0]
    """
    if is_exporting():
        # Exported as three broadcast products summed: onnxruntime's CPU Einsum ran 3 to 5 times slower, and a
        # MatMul runs in bfloat16 at OpenVINO's default precision, coefficients and all (7.1 codes p99.9 on the look).
        return matrix_on_planes(matrix, [image[..., j : j + 1, :, :] for j in range(3)])
    return matrix_on_planes(matrix, image.split(1, dim=-3))


def matrix_on_planes(matrix: torch.Tensor, planes) -> torch.Tensor:
    """:func:`apply_matrix` on an image given as its three planes ``(..., 1, H, W)``: ``sum_j matrix[..., :, j] planes[j]``.

    A product and two ``addcmul`` (in place where nothing records), or, exported, three products summed (the form
    every exported matrix takes). Forms that already hold an image's planes pass them here instead of joining them into
    a frame that the matrix would only slice apart again (a concatenation is a pass over the frame).

    Examples:
        >>> matrix_on_planes(torch.eye(3), torch.arange(3.0).reshape(3, 1, 1, 1).unbind()).flatten().tolist()
        [0.0, 1.0, 2.0]
    """
    if is_exporting():
        return sum(matrix[..., :, j, None, None] * plane for j, plane in enumerate(planes))
    columns = matrix.mT[..., None, None].unbind(-4)
    out = columns[0] * planes[0]
    in_place = untracked(matrix, *planes)
    for column, plane in zip(columns[1:], planes[1:]):
        out = out.addcmul_(column, plane) if in_place else torch.addcmul(out, column, plane)
    return out


def rows_on_planes(rows, planes) -> tuple:
    """A 3x3 matrix of plain numbers (``rows``, nested tuples as :func:`~torchgrade.runtime.values_of` gives) on an
    image's three planes, returned as three planes: ``out_i = sum_j rows[i][j] planes[j]``.

    The form of a chain computed on planes (:attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`): every step
    loops over the pixels once, and the numbers are written into a compiled kernel.

    Examples:
        >>> swap = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        >>> [float(p) for p in rows_on_planes(swap, (torch.tensor(1.0), torch.tensor(2.0), torch.tensor(3.0)))]
        [2.0, 1.0, 3.0]
    """
    red, green, blue = planes
    return tuple(row[0] * red + row[1] * green + row[2] * blue for row in rows)


def each_plane(function, x):
    """``function`` of an image, or of each of its three planes given as a tuple
    (:attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`), returned in the same form.

    Examples:
        >>> each_plane(torch.neg, (torch.tensor(1.0), torch.tensor(2.0), torch.tensor(3.0)))
        (tensor(-1.), tensor(-2.), tensor(-3.))
    """
    return tuple(function(plane) for plane in x) if isinstance(x, tuple) else function(x)


def per_channel(function, x, *coefficients):
    """``function(image, *coefficients)`` of an image and per-channel coefficients ``(..., 3, 1, 1)``; of an image given
    as its three planes (a tuple, :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`), ``function`` of each plane
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

    Three passes over the planes (a product and two adds by a number, in place where nothing records): no weight
    tensor to make or copy, and faster on the CPU than a product and a channel reduction (35 against 71 µs a strip).

    Examples:
        >>> channel_sum(torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1), (0.5, 0.25, 0.0)).flatten().tolist()
        [1.0]
    """
    red, green, blue = image if isinstance(image, tuple) else image.split(1, dim=-3)  # or its planes, as a tuple
    out = red * weights[0]
    if is_exporting() or not untracked(red, green, blue):
        # exported as three products and two sums (a ReduceSum over channels costs onnxruntime's CPU several of them,
        # benchmarks/results/onnx_ops.md)
        return out + green * weights[1] + blue * weights[2]
    return out.add_(green, alpha=weights[1]).add_(blue, alpha=weights[2])


def matrix_product(second: torch.Tensor, first: torch.Tensor) -> torch.Tensor:
    """``second @ first`` for (3, 3) or (B, 3, 3) colour matrices, as broadcast products summed: elementwise work
    that Inductor fuses, where a product of 3x3 matrices is a matrix-library call of its own (see :func:`apply_matrix`).

    Examples:
        >>> a, b = torch.rand(2, 3, 3), torch.rand(3, 3)
        >>> bool(torch.allclose(matrix_product(a, b), a @ b))
        True
    """
    return (second[..., :, :, None] * first[..., None, :, :]).sum(dim=-2)


def check_range(value: Param, name: str, low: float, high: float) -> None:
    """Raise ``ValueError`` naming ``name`` and its range when a concrete value lies outside [low, high].

    Tensors that require grad are checked too (on detached values); NaN parameters are rejected.

    Examples:
        >>> check_range(150.0, 'contrast', -100.0, 100.0)
        Traceback (most recent call last):
        ...
        ValueError: contrast must lie in [-100.0, 100.0], got 150.0
    """
    t = value.detach() if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float64)
    if t.numel() == 0:
        return
    if torch.isnan(t).any() or (t < low).any() or (t > high).any():
        raise ValueError(f"{name} must lie in [{low}, {high}], got {t.tolist()}")


def check_choice(name: str, value, choices) -> None:
    """Raise ``ValueError`` naming ``name`` and the allowed ``choices`` unless ``value`` is one of them.

    Examples:
        >>> check_choice('metering', 'spot', ('mean', 'log'))
        Traceback (most recent call last):
        ...
        ValueError: metering must be one of 'mean', 'log', got 'spot'
    """
    if value not in tuple(choices):
        raise ValueError(f"{name} must be one of {', '.join(map(repr, choices))}, got {value!r}")


def _flat(value) -> list:
    """A number or nested sequence of numbers as a flat list of floats."""
    return [float(item) for part in value for item in _flat(part)] if isinstance(value, (list, tuple)) else [float(value)]


def check_on_cpu(transform, what: str) -> None:
    """Raise ``ValueError`` naming the devices when ``transform`` (an ``nn.Module``) holds tensors off the CPU.

    Baking and ONNX export evaluate on the CPU; a look trained on a GPU is moved with ``look.cpu()``.

    Examples:
        >>> module = torch.nn.Module()
        >>> module.register_buffer("table", torch.zeros(2, device="meta"))
        >>> check_on_cpu(module, "bake_lut")
        Traceback (most recent call last):
        ValueError: bake_lut evaluates on the CPU, but the look holds tensors on meta: pass look.cpu()
    """
    if not isinstance(transform, torch.nn.Module):
        return
    devices = sorted({str(t.device) for t in (*transform.parameters(), *transform.buffers()) if t.device.type != "cpu"})
    if devices:
        raise ValueError(f"{what} evaluates on the CPU, but the look holds tensors on {', '.join(devices)}: pass look.cpu()")


def readable(value) -> bool:
    """Whether ``value`` can be checked in a forward pass without waiting for a device: a plain value, or a tensor
    where the device's policy reads values (the CPU), outside tracing.

    Examples:
        >>> readable(0.5), readable(torch.tensor(0.5)), readable(torch.tensor(0.5, device="meta"))
        (True, True, False)
    """
    if not isinstance(value, torch.Tensor):
        return True
    return not is_tracing() and policy_for(value.device).reads_values


def is_constant(value, constant) -> bool:
    """True when ``value`` is a plain (non-learnable) value equal to ``constant`` everywhere.

    Learnable parameters (``requires_grad``) are never constant: they may move during training; nor are tensors
    differentiated another way (:func:`~torchgrade.runtime.recording.is_differentiated`), tensors while ``torch.compile`` traces, or tensors off the
    CPU (reading one back would wait for the device).

    Examples:
        >>> is_constant((0.5, 0.5, 0.5), 0.5), is_constant(torch.nn.Parameter(torch.tensor(0.5)), 0.5)
        (True, False)
    """
    if isinstance(value, torch.Tensor) and (value.requires_grad or is_differentiated(value)):
        return False
    if isinstance(value, (numbers.Real, list, tuple)):
        # Plain values are compared in Python: a tensor made here would be traced while compiling (reading its
        # value back is a graph break), and eager, a grade in strips asks a hundred times a frame.
        try:
            values, target = _flat(value), _flat(constant)
        except (TypeError, ValueError):
            return False
        if len(values) == 1 or len(target) == 1:  # one number against many broadcasts
            return all(v == t for v in values for t in target)
        return values == target
    if torch.compiler.is_compiling() or (isinstance(value, torch.Tensor) and not policy_for(value.device).reads_values):
        return False  # a tensor's value is not read while compiling, nor off the CPU (a sync): its step is kept
    try:
        value = torch.as_tensor(value, dtype=torch.float64, device="cpu")
        return bool((value == torch.as_tensor(constant, dtype=torch.float64)).all())
    except (TypeError, ValueError, RuntimeError):
        return False


_LOW_PRECISION = (torch.float16, torch.bfloat16)


def working_dtype(image: torch.Tensor) -> torch.Tensor:
    """float16/bfloat16 images are computed in float32 (no silent overflow); others as they are.

    Examples:
        >>> working_dtype(torch.zeros(1, dtype=torch.float16)).dtype, working_dtype(torch.zeros(1, dtype=torch.float64)).dtype
        (torch.float32, torch.float64)
    """
    return image.float() if image.dtype in _LOW_PRECISION else image


def to_input_dtype(result: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    """Cast a float32 result back to the input's low-precision dtype, bounded to its finite range.

    Examples:
        >>> half = torch.zeros(1, dtype=torch.float16)
        >>> to_input_dtype(torch.tensor([1e6]), half).tolist()  # bounded to half's finite range
        [65504.0]
    """
    if result.dtype == image.dtype:
        return result
    return result.clamp(-HALF_MAX, HALF_MAX).to(image.dtype)


_AUTOCAST_DEVICES = ("cpu", "cuda")


@contextlib.contextmanager
def full_precision():
    """Turn off every active ``torch.autocast`` for the block: torchgrade's maths keeps float32 or better.

    Autocast would run the colour matrices (``einsum``) and FFTs in bfloat16/float16 whatever the
    input's dtype, 43 8-bit codes off on a real image; reduced precision is instead chosen by the
    input's dtype (:func:`working_dtype`). Inactive autocast costs nothing: no context is entered.

    Examples:
        >>> with torch.autocast("cpu", dtype=torch.bfloat16), full_precision():
        ...     (torch.ones(2, 2) @ torch.ones(2, 2)).dtype
        torch.float32
    """
    # One device a level, as plain ``with`` blocks: torch.compile traces those (an ExitStack's enter_context it refuses).
    device = next((device for device in _AUTOCAST_DEVICES if torch.is_autocast_enabled(device)), None)
    if device is None:
        yield
        return
    with torch.autocast(device, enabled=False), full_precision():
        yield


@contextlib.contextmanager
def one_thread():
    """Run the block with one intra-op CPU thread, then restore the count (thread-local under OpenMP and MKL).

    Examples:
        >>> import torch
        >>> before = torch.get_num_threads()
        >>> with one_thread():
        ...     torch.get_num_threads()
        1
        >>> torch.get_num_threads() == before
        True
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


_LOG2_HALF_MAX = math.log2(HALF_MAX)


def bounded_pow(x: torch.Tensor, exponent) -> torch.Tensor:
    """``max(x, 0) ** exponent`` for ``exponent >= 0``, bounded to ``HALF_MAX``, with finite gradients everywhere.

    A documented control may raise an HDR value to a large power (OpenColorIO's gamma 0.01 is a
    power of 100, Unity's gamma trackball at its minimum a power of 1000): the result saturates at
    the non-finite policy's bound instead of overflowing to Inf, where a gradient would be NaN.
    Below the bound the value is ``x ** exponent`` exactly, down to the smallest normal number: a positive ``x`` below it
    (a denormal) is taken as it, since the slope ``e x^(e-1)`` of a power below 1 overflows there (a linear contrast of
    0.12, a power of 0.12, gave infinite gradients at 1e-45).

    Examples:
        >>> bounded_pow(torch.tensor([-1.0, 0.0, 4.0, 1e3]), 2.0).tolist()
        [0.0, 0.0, 16.0, 65504.0]
    """
    exponent = torch.as_tensor(exponent, dtype=x.dtype, device=x.device)
    if is_exporting():
        # Without the gradient guard's two Where nodes (see benchmarks/results/onnx_ops.md); the same values for
        # exponent > 0 (at exponent 0, 1 where x <= 0: both callers multiply by sign(x)).
        return (x.clamp_min(0.0) ** exponent).clamp_max(HALF_MAX)
    limit = torch.exp2(_LOG2_HALF_MAX / exponent.detach())
    inside = (x > 0) & (x < limit)
    powered = where(inside, x.clamp_min(torch.finfo(x.dtype).tiny), 1.0) ** exponent
    return torch.where(inside, powered, (x > 0).to(x.dtype) * HALF_MAX)
