"""The compiled CPU forms of the tetrahedral and trilinear lookups (``lookup.c``): sanitize, domain, cell and
interpolation in one pass per pixel, on a packed ``(S³, 3)`` table: over whole frames in chunks spread over torch's
intra-op threads, or on one thread over the runs of :func:`~torchgrade.lut.apply.chunked_lookup`.

:func:`~torchgrade.lut.apply.chunked_lookup` runs it when the C file compiles here
(:func:`torchgrade.runtime.native.native_library`); otherwise the torch form
(:class:`~torchgrade.lut.kernels.TetrahedralRuns`, or trilinear's gather form on runs) runs. Each gives its gather
form's values to float rounding (``tests/lut/test_lut_eager.py`` holds every form to the gather form).
``benchmarks/bench_lut_cpu.py`` times it against OpenColorIO.

Examples:
    >>> import torch
    >>> from torchgrade.lut import identity_table
    >>> interpolate = compiled_loop("tetrahedral", torch.float32)
    >>> x, out = torch.tensor([[0.25], [0.5], [1.5]]), torch.empty(3, 1)
    >>> packed = identity_table(3).reshape(-1, 3).contiguous()
    >>> interpolate is None or interpolate(x[None], out[None], torch.zeros(3), torch.full((3,), 2.0), packed, 3).flatten().tolist()
    [0.25, 0.5, 1.0]
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path
from typing import Callable, Optional

import torch

from ..runtime.native import native_library
from ..runtime.policy import LOOKUP_CHUNK

__all__ = ["compiled_loop", "MAX_SIZE", "SOURCE", "LOOPS"]

SOURCE = Path(__file__).with_name("lookup.c")

MAX_SIZE = 812
"""The largest lattice the compiled loop takes: its 32-bit indices reach ``3 S³``, below 2³¹."""

LOOPS = ("tetrahedral", "trilinear")
"""The interpolations ``lookup.c`` has a loop for."""

_TYPES = {torch.float32: "float", torch.float64: "double"}


@functools.lru_cache(maxsize=None)
def compiled_loop(interpolation: str, dtype: torch.dtype) -> Optional[Callable]:
    """``interpolate(x, out, low, scale, packed, size, chunk=LOOKUP_CHUNK)``: ``interpolation`` (one of :data:`LOOPS`)
    for ``dtype`` (float32 or float64), or ``None`` where the C file does not compile here or there is no such loop.

    ``x`` and ``out`` are ``(N, 3, n)`` frames whose rows are contiguous, ``low`` the domain's low end and ``scale``
    ``(S - 1) / span`` ``(3,)`` in the shaper's codes, ``packed`` the contiguous ``(S³, 3)`` table, all of ``dtype`` on
    the CPU; chunks of ``chunk`` pixels go to ``torch.get_num_threads()`` threads. Returns ``out``. Nothing is checked
    here: :func:`~torchgrade.lut.apply.chunked_lookup` passes what it made.
    """
    library = native_library(SOURCE) if dtype in _TYPES and interpolation in LOOPS else None
    if library is None:
        return None
    function = getattr(library, f"{interpolation}_{_TYPES[dtype]}")
    pointer, count = ctypes.c_void_p, ctypes.c_int64
    function.argtypes = [pointer, count, count, pointer, count, count, count, count, pointer, pointer, pointer, ctypes.c_int32,
                         count, ctypes.c_int32]
    function.restype = None

    def interpolate(x: torch.Tensor, out: torch.Tensor, low: torch.Tensor, scale: torch.Tensor, packed: torch.Tensor,
                    size: int, chunk: int = LOOKUP_CHUNK) -> torch.Tensor:
        function(x.data_ptr(), x.stride(0), x.stride(1), out.data_ptr(), out.stride(0), out.stride(1), x.shape[0], x.shape[-1],
                 low.data_ptr(), scale.data_ptr(), packed.data_ptr(), size, chunk, torch.get_num_threads())
        return out

    return interpolate
