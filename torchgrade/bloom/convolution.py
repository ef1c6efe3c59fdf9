"""Convolution bloom (Unreal's): the thresholded image convolved with a user kernel, by FFT or directly.

The kernel is the glow of a point light. The thresholded frame is extended by its mirror image about the edge
(:func:`~torchgrade.bloom.blur.mirror_pad`, the pyramid bloom's edge rule) before it is convolved: a uniform
frame blooms uniformly, and a frame turned or mirrored blooms turned or mirrored (with a kernel symmetric the same
way). The convolution itself is zero-padded, so nothing wraps around. ONNX has no FFT at opset 17, so :meth:`ConvolutionBloom.export_form` gives a
module that convolves directly (:func:`direct_convolve`): the same result, slower for large kernels.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..base.images import check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import Param, check_range, is_constant, scalar_param
from ..base.controls import Control
from ..base.stage import Stage
from .layer import CONTROLS
from .prefilter import threshold_fraction
from .blur import mirror_pad
from .texture import as_texture, check_texture

__all__ = ["fft_convolve", "direct_convolve", "check_kernel", "convolution_bloom", "ConvolutionBloom", "DirectConvolutionBloom"]

PREFILTER_CONTROLS = ("threshold", "knee", "intensity")


def fft_convolve(light: torch.Tensor, kernel: torch.Tensor) -> torch.Tensor:
    """``light`` ``(..., H, W)`` convolved with an odd-sided ``kernel`` centred on its middle pixel, zero outside.

    Both are zero-padded to ``(H + kh - 1, W + kw - 1)`` before ``torch.fft.rfft2``, so the
    circular convolution equals the linear one (nothing wraps around); the frame is then cropped.

    Examples:
        >>> light = torch.zeros(1, 3, 5, 5); light[..., 0, 0] = 1.0
        >>> fft_convolve(light, torch.ones(3, 3, 3))[0, 0, :3, :3].abs().round(decimals=4)
        tensor([[1., 1., 0.],
                [1., 1., 0.],
                [0., 0., 0.]])
    """
    kh, kw = kernel.shape[-2:]
    size = (light.shape[-2] + kh - 1, light.shape[-1] + kw - 1)
    spectrum = torch.fft.rfft2(light, s=size) * torch.fft.rfft2(kernel, s=size)
    full = torch.fft.irfft2(spectrum, s=size)
    return full[..., kh // 2 : kh // 2 + light.shape[-2], kw // 2 : kw // 2 + light.shape[-1]]


def direct_convolve(light: torch.Tensor, kernel: torch.Tensor) -> torch.Tensor:
    """:func:`fft_convolve` as a direct ``conv2d`` (the kernel flipped, zero padding, one group per
    channel): the same linear convolution, in operators every ONNX runtime has.

    Examples:
        >>> light, kernel = torch.rand(1, 3, 6, 7, dtype=torch.float64), torch.rand(3, 3, 5, dtype=torch.float64)
        >>> bool(torch.allclose(direct_convolve(light, kernel), fft_convolve(light, kernel)))
        True
    """
    kh, kw = kernel.shape[-2:]
    weight = kernel.expand(3, kh, kw).flip(-2, -1).unsqueeze(1)
    return F.conv2d(light, weight, padding=(kh // 2, kw // 2), groups=3)


def check_kernel(kernel) -> None:
    """Raise unless ``kernel`` is a finite ``(1 or 3, kh, kw)`` tensor with odd sides and a positive sum per channel.

    Examples:
        >>> check_kernel(torch.ones(1, 4, 3))
        Traceback (most recent call last):
        ...
        ValueError: kernel must have odd sides so that its centre is a pixel, got (1, 4, 3)
    """
    check_texture(kernel, "kernel", odd_sides=True)
    if not bool((kernel.detach().sum(dim=(-2, -1)) > 0).all()):
        raise ValueError("kernel must have a positive sum in every channel (it is normalised to sum 1)")


def convolution_bloom(
    image: torch.Tensor, kernel: torch.Tensor, threshold: Param = 1.0, knee: Param = 0.5, intensity: Param = 1.0
) -> torch.Tensor:
    """Unreal's convolution bloom: ``image + intensity * (T(image) conv k)``, by FFT (:func:`fft_convolve`).

    ``T`` is :func:`~torchgrade.bloom.bloom_threshold` at full resolution; ``kernel`` ``(1 or 3, kh, kw)``
    with odd sides is the glow of a point light (centred, normalised to sum 1 per channel), so a
    point's light reappears as the kernel image around it. Beyond the frame the convolution sees the frame's mirror
    image, so a uniform frame gains a uniform glow.

    Examples:
        >>> image = torch.zeros(1, 3, 5, 5); image[..., 2, 2] = 10.0
        >>> out = convolution_bloom(image, torch.ones(1, 3, 3), threshold=0.0, knee=0.0)
        >>> round(float(out[0, 0, 1, 1]), 4), round(float(out.sum() / image.sum()), 4)
        (1.1111, 2.0)
        >>> uniform = convolution_bloom(torch.full((1, 3, 4, 6), 2.0), torch.ones(1, 5, 3), threshold=0.0, knee=0.0)
        >>> round(float(uniform.min()), 4), round(float(uniform.max()), 4)
        (4.0, 4.0)
    """
    check_image(image)
    check_kernel(kernel)
    for name, value in zip(PREFILTER_CONTROLS, (threshold, knee, intensity)):
        check_range(value, name, *CONTROLS[name].range)
    return _convolved(image, kernel, threshold, knee, intensity, fft_convolve)


def _convolved(image, kernel, threshold, knee, intensity, convolve, *, nan_free: bool = False,
               any_size: bool = False) -> torch.Tensor:
    """:func:`convolution_bloom` on checked arguments, convolving with ``convolve``; ``nan_free``: ``image`` holds no
    NaN (:func:`~torchgrade.base.images.sanitize`); ``any_size``: the mirror's general form, for a graph that serves
    frames of any size (:func:`~torchgrade.bloom.blur.mirror_pad`)."""
    if is_constant(intensity, 0.0):
        return image
    height, width = image.shape[-2:]
    scene = sanitize(working_dtype(image), nan_free=nan_free).reshape(-1, 3, height, width)
    reference = scene if image.dim() == 4 else scene[0]
    threshold, knee, intensity = (
        scalar_param(value, reference, name) for name, value in zip(PREFILTER_CONTROLS, (threshold, knee, intensity))
    )
    kernel = kernel.to(scene.dtype)
    radius = (kernel.shape[-2] // 2, kernel.shape[-1] // 2)
    extended = mirror_pad(scene * threshold_fraction(scene, threshold, knee), radius, any_size)
    glow = convolve(extended, kernel / kernel.sum(dim=(-2, -1), keepdim=True))
    glow = glow.narrow(-2, radius[0], height).narrow(-1, radius[1], width)
    return to_input_dtype((scene + intensity * glow).reshape(image.shape), image)


class ConvolutionBloom(Stage):
    """Convolution bloom stage; ``ConvolutionBloom(kernel, ...)(image)`` is :func:`convolution_bloom`.

    ``kernel`` (a tensor, or nested lists from a config) is kept as a buffer, or as a parameter when
    given as ``nn.Parameter``; the other controls are stored as :class:`~torchgrade.Bloom` stores them.

    Examples:
        >>> stage = ConvolutionBloom([[[0.0, 1.0, 0.0]]], intensity=0.5)
        >>> stage.to_config()
        {'kernel': [[[0.0, 1.0, 0.0]]], 'threshold': 1.0, 'knee': 0.5, 'intensity': 0.5}
        >>> stage.is_identity, ConvolutionBloom(torch.ones(1, 3, 3), intensity=0).is_identity
        (False, True)
    """

    controls = {"kernel": Control(None), **{name: CONTROLS[name] for name in PREFILTER_CONTROLS}}
    always_in_config = tuple(controls)

    def __init__(self, kernel, threshold: Param = 1.0, knee: Param = 0.5, intensity: Param = 1.0) -> None:
        super().__init__()
        self.init_controls(kernel=kernel, threshold=threshold, knee=knee, intensity=intensity)

    def check_control(self, name: str, value):
        """``kernel`` checked (:func:`check_kernel`) and kept as a tensor; numbers kept as floats."""
        if name == "kernel":
            value = as_texture(value)
            check_kernel(value)
            return value
        return value if isinstance(value, torch.Tensor) else float(value)

    def check_learnable(self) -> None:
        """Also check a learnable kernel, which an optimiser may move to a zero sum or to NaN: once per change of the
        kernel, without waiting for a GPU (:class:`~torchgrade.runtime.DeferredCheck`)."""
        super().check_learnable()
        if isinstance(self.kernel, nn.Parameter):
            self.deferred_check()({"kernel": self.kernel}, lambda name, kernel: check_kernel(kernel))

    @property
    def is_identity(self) -> bool:
        """True when ``intensity`` is a plain 0."""
        return is_constant(self.intensity, 0.0)

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        check_image(image)
        return _convolved(image, self.kernel, self.threshold, self.knee, self.intensity, fft_convolve, nan_free=nan_free)

    def export_form(self) -> nn.Module:
        """The form an ONNX graph runs: :class:`DirectConvolutionBloom` (no FFT at opset 17)."""
        return DirectConvolutionBloom(self)


class DirectConvolutionBloom(nn.Module):
    """:class:`ConvolutionBloom` convolving directly (:func:`direct_convolve`): the same result in ONNX's operators, its
    mirror in the form of any frame size (one exported graph serves every size).

    Examples:
        >>> stage = ConvolutionBloom(torch.rand(3, 5, 5) + 0.1, threshold=0.5)
        >>> image = torch.rand(1, 3, 8, 9) * 4
        >>> bool(torch.allclose(DirectConvolutionBloom(stage)(image), stage(image), atol=1e-5))
        True
    """

    takes_nan_free = True  # as the stage (Stage.takes_nan_free)

    def __init__(self, stage: ConvolutionBloom):
        super().__init__()
        self.stage = stage

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        check_image(image)
        stage = self.stage
        return _convolved(image, stage.kernel, stage.threshold, stage.knee, stage.intensity, direct_convolve, nan_free=nan_free,
                          any_size=True)
