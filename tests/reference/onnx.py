"""What the ONNX tests share: the shapes every exported model is run at, tolerances, and test frames."""

import torch

from torchgrade.onnx import verify

SHAPES = [(1, 3, 37, 53), (3, 3, 64, 96)]
"""Two batch sizes, two resolutions (the first odd in both sides); exports trace at (2, 3, 64, 64)."""
TOLERANCE = 1e-4
STEP_TOLERANCE = 1e-3
"""A grade_inputs graph evaluates every grading step; PyTorch skips steps at identity, and some identity
evaluations are not exact (white balance at temperature = tint = 0 is Unity's formula, gains 1 +- 1e-6,
and split toning's gamma round trip). Looks with such steps left at identity agree to this (display)."""

def hdr(shape, seed=1) -> torch.Tensor:
    """Scene-referred noise: mostly below 2, a tail up to ~60, some exact zeros."""
    generator = torch.Generator().manual_seed(seed)
    image = torch.rand(shape, generator=generator) ** 4 * 60.0
    image[..., ::7, ::5] = 0.0
    return image


def display_error(module, path, inputs) -> float:
    """verify()'s max abs error, relative to the output's peak where that exceeds 1 (scene-referred stages)."""
    with torch.no_grad():
        peak = float(module(inputs).abs().max())
    return verify(module, path, inputs) / max(1.0, peak)
