"""Accuracy and memory measures of the benchmark: errors in what a viewer sees, peak memory of a call.

Errors compare display-referred linear images (a look's output) after encoding them as a display
does: clamp to [0, 1], sRGB-encode, scale to 8-bit code values (not rounded, so a fraction of a code
is visible). ΔE2000 is computed by colour-science on CIE Lab (D65) of those sRGB values.
"""

from __future__ import annotations

import ctypes
import functools
import math
import warnings
from pathlib import Path

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


# ---------------------------------------------------------------- peak memory


def _status_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


@functools.lru_cache(maxsize=None)
def _glibc():
    """glibc through ctypes, or None where there is no ``libc.so.6`` (not Linux with glibc)."""
    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        return None


def map_large_buffers() -> bool:
    """Make glibc serve every allocation above 64 KiB with its own mapping, returned to the system on free.

    Peak resident memory then rises and falls with each buffer, so :func:`peak_rss_mb` sees what a
    call allocates instead of heap pages kept from earlier calls. Slows allocation: call it after
    every timing. Returns False where glibc's ``mallopt`` is not available.
    """
    libc = _glibc()
    if libc is None:
        return False
    m_mmap_threshold, m_trim_threshold = -3, -1
    return bool(libc.mallopt(m_mmap_threshold, 65536)) and bool(libc.mallopt(m_trim_threshold, 0))


def release_free_memory() -> None:
    """Hand the heap's free pages back to the system (glibc ``malloc_trim``); a no-op without glibc."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


def peak_rss_mb(run) -> float | None:
    """Peak resident memory (MiB) that ``run()`` adds to the process, its output included.

    Free heap pages are released first, so reusing them counts as growth, and again after ``run``
    (the kernel updates its peak-RSS counter when pages are unmapped); the counter is reset before
    ``run`` through ``/proc/self/clear_refs``. ``None`` where that file is not available (not Linux).
    """
    release_free_memory()
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return None
    before = _status_kib("VmRSS")
    run()
    release_free_memory()
    return max(0, _status_kib("VmHWM") - before) / 1024.0


def peak_cuda_mb(run, device) -> float:
    """Peak CUDA memory (MiB) that ``run()`` allocates beyond what was allocated before."""
    torch.cuda.synchronize(device)
    torch.cuda.reset_peak_memory_stats(device)
    before = torch.cuda.memory_allocated(device)
    run()
    torch.cuda.synchronize(device)
    return (torch.cuda.max_memory_allocated(device) - before) / 2**20
