"""Images and their checks: shape and dtype, an alpha channel passed through, the non-finite policy and the precision a
stage computes in (floats that look like 8-bit pictures warn: :func:`~torchgrade.runtime.checks.warn_if_eight_bit`).

* Images are float tensors ``(..., 3, H, W)`` (a stage also takes ``(..., 4, H, W)``, its alpha passed through:
  :func:`with_alpha`); anything else is a ``TypeError`` (dtype) or a ``ValueError`` (shape), with a message naming
  the problem and the caller's shape.
* **Non-finite policy** (:func:`sanitize`): NaN becomes 0 and every value is bounded to
  ``[-HALF_MAX, HALF_MAX]`` (±65504, the range of the half-float HDR buffers that engines render
  to), so ±Inf becomes ±65504. Stages that mix pixels (bloom, metering) or raise values to powers
  apply it first, so one bad pixel never spreads and intermediate sums never overflow in float32.
  Scene-referred values inside that range are never clamped.
"""

from __future__ import annotations

import contextlib

import torch

from ..runtime.strips import named_as

__all__ = ["HALF_MAX", "NEGLIGIBLE_LIGHT", "check_image", "with_alpha", "check_on_cpu", "sanitize",
           "working_dtype", "to_input_dtype", "full_precision"]

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


def sanitize(image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
    """Apply the non-finite policy: NaN -> 0, values bounded to [-65504, 65504] (so ±Inf -> ±65504).

    NaN is found on the input itself, before the bound (OpenVINO's ``Clip`` turns NaN into its lower bound).
    ``nan_free``: the caller knows ``image`` holds no NaN (a stage's output never does:
    ``tests/library/test_extremes.py``), so only the bound is applied, without the NaN pass over the frame (a kernel,
    or ``IsNaN`` and ``Where`` in an exported graph).

    Examples:
        >>> x = torch.tensor([float('nan'), float('inf'), -1.0])
        >>> sanitize(x).tolist()
        [0.0, 65504.0, -1.0]
        >>> sanitize(x, nan_free=True).tolist()  # the caller's word is taken: only bounded
        [nan, 65504.0, -1.0]
    """
    if not nan_free:
        image = image.nan_to_num(nan=0.0)
    return image.clamp(-HALF_MAX, HALF_MAX)


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
