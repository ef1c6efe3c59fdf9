"""Accuracy measures of the benchmarks: errors in what a viewer sees.

Errors compare display-referred linear images (a look's output) after encoding them as a display
does: clamp to [0, 1], sRGB-encode, scale to 8-bit code values (not rounded, so a fraction of a code
is visible). ΔE2000 is computed by colour-science on CIE Lab (D65) of those sRGB values.
Used by ``benchmarks/run.py``, ``bench_lut.py`` and ``lut_floor.py``; checked by ``tests/project/test_benchmarks.py``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import torch

from torchgrade.color import linear_to_srgb

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # colour-science warns that SciPy is absent; ΔE2000 does not need it
    import colour

D65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]


def srgb_codes(display: torch.Tensor) -> torch.Tensor:
    """8-bit sRGB code values (float64, unrounded) of display-referred linear values: ``255 srgb(clamp(x, 0, 1))``."""
    return 255.0 * linear_to_srgb(display.detach().cpu().double().clamp(0.0, 1.0))


def quantile(values: torch.Tensor, q: float) -> float:
    """The ``q`` quantile of ``values`` as the ``ceil(q n)``-th smallest value (no interpolation)."""
    flat = values.flatten()
    return float(flat.kthvalue(max(1, math.ceil(q * flat.numel()))).values)


def code_error_summary(reference_codes: torch.Tensor, codes: torch.Tensor) -> dict:
    """Max and 99.9th-percentile absolute difference of two code-value images, over every channel of every pixel."""
    error = (reference_codes - codes).abs()
    return {"max_error_8bit": float(error.max()), "p999_error_8bit": quantile(error, 0.999)}


def pixels_of(codes: torch.Tensor) -> np.ndarray:
    """``(..., 3, H, W)`` code values as an ``(N, 3)`` array of sRGB values in [0, 1]."""
    return (codes.movedim(-3, -1).reshape(-1, 3) / 255.0).numpy()


def delta_e2000(reference_codes: torch.Tensor, codes: torch.Tensor) -> np.ndarray:
    """Per-pixel CIE ΔE2000 between two code-value images (sRGB, D65)."""
    lab = [colour.XYZ_to_Lab(colour.sRGB_to_XYZ(pixels_of(c)), D65) for c in (reference_codes, codes)]
    return colour.delta_E(lab[0], lab[1], method="CIE 2000")


def sample_indices(pixels: int, count: int, seed: int = 0) -> torch.Tensor:
    """``count`` distinct pixel indices out of ``pixels`` (all of them when ``count >= pixels``), fixed by ``seed``."""
    if count >= pixels:
        return torch.arange(pixels)
    return torch.randperm(pixels, generator=torch.Generator().manual_seed(seed))[:count]
