"""Where a frame is computed, and how: the execution policy of each device, decided here and nowhere else.

A per-pixel stage is dozens of elementwise operations. How they should run depends on the device, not on the
maths, so the maths modules keep one differentiable form each and ask :func:`policy_for`:

* **CPU**: strips of rows of :data:`STRIP_PIXELS_PER_THREAD` pixels per intra-op thread, so that each thread's
  share of a strip's intermediates stays in its core's cache while every operation uses all the threads. A value
  of the data may be read back (free on the CPU), and blurs and pooling take the slices the CPU is fastest at.
* **Any other device** (CUDA, ``meta``, ...): whole frames. Each operation is a kernel launch there, and a strip
  loop multiplies launches for no cache to gain (``benchmarks/results/gpu.md``, the stages' "before (strips / none)");
  a value read back is a synchronisation, so no eager shortcut reads one; blurs and pooling are one library kernel
  each.
* **While tracing, compiling or exporting**: one graph of whole frames, no reads. While compiling, per-pixel chains
  run on the image's three planes (:attr:`ExecutionPolicy.pixel_planes`), which the compiler fuses into one kernel.

Examples:
    >>> import torch
    >>> policy_for(torch.device("meta")).strip_pixels is None
    True
    >>> policy_for(torch.device("cpu")).strip_pixels == STRIP_PIXELS_PER_THREAD * torch.get_num_threads()
    True
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, replace
from typing import Optional

import torch

from .constants import scalar
from .recording import is_tracing

__all__ = ["ExecutionPolicy", "policy_for", "readable", "nonnegative", "pixel_layout", "STRIP_PIXELS_PER_THREAD", "ONE_KERNEL_BLUR_PIXELS", "one_thread",
           "CPU_HISTOGRAM_TABLES", "RESAMPLING_MATRIX_SIDE"]

STRIP_PIXELS_PER_THREAD = 1 << 16
"""Pixels of a CPU strip per intra-op thread (batch included): a strip's intermediates stay in the cores' caches,
and each of its dozens of operations is dispatched by Python once a strip, so smaller strips pay that more often and
much larger ones leave the cache; twice this size runs about as fast on 2 cores (grade and tone map of
``export/looks/cinematic.json`` at 1920x1080 in strips of 2^15 to 2^19 pixels a thread and whole:
``benchmarks/results/cpu_forms.md``, "Strips"). A strip grows with the thread count: each thread's share stays that
size, and a frame on many cores is fewer strips."""


@dataclass(frozen=True)
class ExecutionPolicy:
    """How a device computes a frame.

    Attributes:
        strip_pixels: pixels per strip of a per-pixel stage, or ``None`` for whole frames.
        reads_values: eager shortcuts may read a value of the data (bloom skips its pyramid when no pixel
            passes the threshold): free on the CPU, a synchronisation of the device elsewhere.
        filters_as_kernels: a separable blur as two convolutions with kernels made once, and a 2x2 mean as one
            ``avg_pool2d``: one library kernel each (cuDNN), where the CPU is faster on sums of shifted slices
            (``benchmarks/results/cpu_forms.md``, "bloom blur" and "bloom halving").
        one_kernel_blur_pixels: with ``filters_as_kernels``, a plane of at most this many pixels is blurred by one 2-D
            convolution (taps² products a pixel, one launch) instead of two 1-D ones (one launch each); ``None``: never.
        nan_dropping_max: ``max(x, 0)`` with NaN to 0 as one ``torch.fmax`` (one launch) instead of a clamp and a NaN
            pass; the CPU does not vectorise ``fmax``, slower there than the two passes (``benchmarks/results/cpu_forms.md``, "max(x, 0)").
        histogram_tables: the tables of bins a histogram is counted into, image column ``c`` into table ``c mod
            histogram_tables``, the tables summed after; ``None``: one per column. Neighbouring pixels, often of one
            bin, then add to different addresses instead of each waiting on the one before: on a GPU, atomic
            additions (a 4K frame counted into one table: ``benchmarks/results/gpu.md``, run D's histogram); on the
            CPU, a chain of additions to one address (see :data:`CPU_HISTOGRAM_TABLES`).
        histogram_row_groups: the groups of image rows a histogram is counted by, each into its own tables, the
            groups summed after (the largest number up to this that divides the image's height): ATen's CPU scatter
            runs the rows of its output on threads, one row each, so one row for the whole frame runs on one thread.
            The CPU policy has one group a thread (the cinematic look's exposure stage against one group:
            ``benchmarks/results/cpu_paths.md``).
        resampling_matrix_side: a side of at most this many pixels that bloom resamples to a size other than half or
            twice its own (an odd side) is resampled by its matrix, made once a size (one matrix product), instead of
            by gathers (a gather, a product and a sum a step); ``None``: never (while tracing, compiling or exporting,
            whose sizes are symbolic and whose compilers fuse the gathers).
        pixel_planes: a per-pixel chain that mixes channels (a colour matrix, a channel's maximum, a luminance) runs
            on the image's three planes (the channel dimension unbound), stacked once at its end. Inductor fuses steps
            that loop over the same number of elements: a step on the frame (3 values a pixel) after one on a plane
            (1 a pixel) starts a new kernel, which writes and reads the frame again, so a chain that alternates them
            is several kernels (6 for ``ToneMap("aces")``), and on planes one. Eager, a step on planes is three
            launches instead of one: only while compiling. Read by the ACES curves (``aces``, ACES 2.0 and its table
            gathers) and ``ColorGrade``.
    """

    strip_pixels: Optional[int]
    reads_values: bool
    filters_as_kernels: bool
    one_kernel_blur_pixels: Optional[int] = None
    nan_dropping_max: bool = False
    histogram_tables: Optional[int] = 1
    histogram_row_groups: int = 1
    resampling_matrix_side: Optional[int] = None
    pixel_planes: bool = False


CPU_HISTOGRAM_TABLES = 8
"""Tables a CPU counts a histogram into (:attr:`ExecutionPolicy.histogram_tables`). The CPU adds a pixel to its bin
after the previous pixel's addition, and neighbouring pixels of a frame mostly fall in one bin: each addition then
waits for the one before it at the same address. Eight neighbouring columns in eight tables of 128 bins (4 KiB, in
the core's first-level cache) break that chain (the cinematic look's exposure stage against one table:
``benchmarks/results/cpu_paths.md``). A table per column, a GPU's choice, would not fit that cache (1920 tables of
128 bins at 1080p)."""

ONE_KERNEL_BLUR_PIXELS = 1 << 17
"""Pixels of a plane up to which a GPU blurs it with one 2-D convolution. A 9-tap blur of 2^17 pixels is 10.6 million
products a channel, microseconds on a GPU, against a launch's fixed cost (``benchmarks/gpu_proxy.py``): the deep levels of a
bloom pyramid (from 270x480 at 4K; 8 of its 9 levels) cost their launches, not their arithmetic."""

RESAMPLING_MATRIX_SIDE = {"cpu": 128, "other": 1024}
"""Sides up to which bloom resamples an odd side by its matrix (:attr:`ExecutionPolicy.resampling_matrix_side`). A
matrix product costs ``n · m`` products a row where the gathers cost a few passes: on a GPU, where the deep levels of a
pyramid cost their launches, up to 1024 (every odd level of a 4K frame's pyramid); on the CPU up to 128."""

WHOLE_FRAMES = ExecutionPolicy(strip_pixels=None, reads_values=False, filters_as_kernels=True,
                               one_kernel_blur_pixels=ONE_KERNEL_BLUR_PIXELS, nan_dropping_max=True, histogram_tables=None,
                               resampling_matrix_side=RESAMPLING_MATRIX_SIDE["other"])

GRAPH = ExecutionPolicy(strip_pixels=None, reads_values=False, filters_as_kernels=False)
"""While tracing, compiling or exporting: kornia's blur, which picks its own form for the compiler (convolution on the
CPU, slices that Inductor fuses on CUDA) and exports as before."""

COMPILED = replace(GRAPH, pixel_planes=True)
"""While compiling: a graph whose per-pixel chains run on planes, for Inductor to fuse."""

COMPILED_OFF_CPU = replace(COMPILED, histogram_tables=None)
"""While compiling for a GPU: its scatters Inductor makes atomic additions."""


def policy_for(device: torch.device) -> ExecutionPolicy:
    """The execution policy of ``device``, for the calling thread (its intra-op thread count).

    Examples:
        >>> import torch
        >>> policy_for(torch.device("cuda", 0)) == WHOLE_FRAMES
        True
    """
    if torch.compiler.is_compiling():
        return COMPILED if device.type == "cpu" else COMPILED_OFF_CPU
    if is_tracing():
        return GRAPH
    if device.type != "cpu":
        return WHOLE_FRAMES
    threads = torch.get_num_threads()
    return ExecutionPolicy(strip_pixels=STRIP_PIXELS_PER_THREAD * threads, reads_values=True, filters_as_kernels=False, histogram_tables=CPU_HISTOGRAM_TABLES,
                           histogram_row_groups=threads, resampling_matrix_side=RESAMPLING_MATRIX_SIDE["cpu"])


def nonnegative(x: torch.Tensor) -> torch.Tensor:
    """``max(x, 0)`` with NaN to 0 and +Inf kept, as a new tensor: one ``torch.fmax`` where the device's policy says
    (:attr:`ExecutionPolicy.nan_dropping_max`), else a clamp and a NaN pass in place on it.

    Examples:
        >>> import math
        >>> nonnegative(torch.tensor([-1.0, math.nan, 2.0, math.inf])).tolist()
        [0.0, 0.0, 2.0, inf]
    """
    if policy_for(x.device).nan_dropping_max:
        return torch.fmax(x, scalar(0.0, x))
    return x.clamp_min(0.0).nan_to_num_(nan=0.0, posinf=math.inf)


def pixel_layout(image: torch.Tensor, keepdim: bool = True):
    """``image`` as its device's policy computes per-pixel chains on it: the image itself, or while compiling
    (:attr:`ExecutionPolicy.pixel_planes`) its three planes as a tuple, each ``(..., 1, H, W)`` (``keepdim``) or
    ``(..., H, W)``, which Inductor fuses into one kernel.

    Examples:
        >>> pixel_layout(torch.zeros(1, 3, 2, 2)).shape  # eager: the image
        torch.Size([1, 3, 2, 2])
    """
    if not policy_for(image.device).pixel_planes:
        return image
    return image.split(1, dim=-3) if keepdim else image.unbind(-3)


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
