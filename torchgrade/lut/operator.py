"""``torchgrade::lut_lookup``: a 3D LUT's interpolation as a ``torch.library`` operator, whose CPU kernel is the C loop
built with the package (``lookup.c``, the extension ``torchgrade.lut._lookup``).

For the planar codes ``x`` ``(3, P)`` of ``P`` pixels (linear values, or a shaper's codes), a table ``(S, S, S, 3)``
``[b, g, r, channel]`` of the same dtype and the lattice's domain ``(3,)`` ``low`` and ``high``::

    u = clamp((sanitize(x) - low) / (high - low), 0, 1) * (S - 1)      # lattice coordinates, per channel
    y = interpolate(table, u)                                           # torchgrade.lut.kernels: tetrahedral, trilinear

with the library's non-finite policy (:func:`~torchgrade.base.images.sanitize`; ``nan_free``: ``x`` holds no NaN).
:func:`torch_form` is that formula in torch operations, differentiable: it is what the operator means, and what
runs for it where the C loop does not.

* **CPU kernel**: the C loop, sanitize, domain, cell and interpolation in one pass per pixel over whole frames, in
  chunks of :data:`CHUNK_PIXELS` that torch's own OpenMP threads take as they come free, without the GIL (float32
  and float64). The extension is built at install (``setup.py``); where it was not (no C compiler then) the kernel
  is :func:`torch_form`, with one ``RuntimeWarning`` at the first lookup. Nothing is compiled or loaded at run time.
* **Fake kernel**: the output's shape and dtype, so ``torch.compile(fullgraph=True)`` takes a lookup whole.
* **Autograd**: the gradients of :func:`torch_form` with respect to the codes and the table (``torch.func.vjp``),
  none to the domain.
* **Export**: while ``torch.jit.trace`` records (the TorchScript ONNX exporter), the operator is recorded as
  :func:`torch_form`'s operations (its ``Tracer`` kernel), which the stock symbolics export as ``Gather`` nodes: the
  ``"gather"`` backend's graph. The other backends' grid forms are chosen by the LUT's export form
  (:class:`~torchgrade.lut.LUTLookup`) before anything reaches the operator.

Examples:
    >>> import torch
    >>> from torchgrade.lut import identity_table
    >>> x = torch.tensor([[0.25], [0.5], [1.5]])
    >>> lut_lookup(x, identity_table(3), torch.zeros(3), torch.ones(3), "tetrahedral").flatten().tolist()
    [0.25, 0.5, 1.0]
"""

from __future__ import annotations

import functools
import warnings

import torch
from torch import Tensor

from ..base.images import sanitize
from .kernels import KERNELS
from .lattice import planar_table
from .shapers import lattice_unit

try:
    from . import _lookup as NATIVE
except ImportError:  # built without a C compiler: the torch form runs (one warning at the first lookup)
    NATIVE = None  # type: ignore[assignment]  # (the stub, _lookup.pyi, types the calls made when it is there)

__all__ = ["lut_lookup", "torch_form", "NATIVE", "CHUNK_PIXELS"]

CHUNK_PIXELS = 32768
"""Pixels of a frame a thread takes at a time in the C loop: threads that a loaded core slows take fewer chunks
instead of holding the frame up with a fixed share (``benchmarks/cpu_forms.py``, "LUT runs", times chunks of 2^13 to
2^17 pixels at 1920x1080)."""

_LOOPS = {("tetrahedral", torch.float32): 0, ("tetrahedral", torch.float64): 1, ("trilinear", torch.float32): 2,
          ("trilinear", torch.float64): 3}
"""The C loop of each interpolation and dtype (``lookup.c``'s ``kind``)."""


def torch_form(codes: Tensor, table: Tensor, domain_min: Tensor, domain_max: Tensor, interpolation: str,
               nan_free: bool = False) -> Tensor:
    """:func:`lut_lookup` in torch operations (the module docstring's formula): the interpolation's gather form
    (:data:`~torchgrade.lut.KERNELS`) at the lattice coordinates of every pixel, differentiable.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> x = torch.full((3, 1), float("nan"))
        >>> torch_form(x, identity_table(2), torch.zeros(3), torch.ones(3), "trilinear").flatten().tolist()
        [0.0, 0.0, 0.0]
    """
    size = int(table.shape[0])  # a constant of a traced graph, as the LUT's own size is
    coords = lattice_unit(sanitize(codes, nan_free=nan_free), "linear", domain_min, domain_max) * (size - 1)
    return KERNELS[interpolation](coords, planar_table(table), size)


@torch.library.custom_op("torchgrade::lut_lookup", mutates_args=(), device_types="cpu")
def lut_lookup(codes: Tensor, table: Tensor, domain_min: Tensor, domain_max: Tensor, interpolation: str,
               nan_free: bool = False) -> Tensor:
    """The operator on the CPU (see the module docstring): ``codes`` ``(3, P)`` and ``table`` ``(S, S, S, 3)`` of one
    dtype, ``domain_min`` and ``domain_max`` ``(3,)``; a new contiguous ``(3, P)`` tensor. ``ValueError`` for other
    shapes (the C loop reads what they promise)."""
    _check_arguments(codes, table, domain_min, domain_max, interpolation)
    loop = _LOOPS.get((interpolation, codes.dtype)) if NATIVE is not None and table.dtype == codes.dtype else None
    if loop is None:
        if NATIVE is None:
            _warn_once()
        with torch.no_grad():
            return torch_form(codes, table, domain_min, domain_max, interpolation, nan_free).contiguous()
    return _native(loop, codes, table, domain_min, domain_max)


def _check_arguments(codes: Tensor, table: Tensor, domain_min: Tensor, domain_max: Tensor, interpolation: str) -> None:
    """``ValueError`` unless the arguments have the shapes, dtypes and names :func:`lut_lookup` takes."""
    if interpolation not in KERNELS:
        raise ValueError(f"lut_lookup: interpolation must be one of {', '.join(map(repr, KERNELS))}, got {interpolation!r}")
    size = table.shape[0] if table.dim() == 4 else 0
    if codes.dim() != 2 or codes.shape[0] != 3 or size < 2 or table.shape != (size, size, size, 3):
        raise ValueError(f"lut_lookup takes codes (3, P) and a table (S, S, S, 3) with S >= 2, got {tuple(codes.shape)} and "
                         f"{tuple(table.shape)}")
    if not codes.is_floating_point() or table.dtype != codes.dtype:
        raise ValueError(f"lut_lookup takes codes and a table of one floating-point dtype, got {codes.dtype} and {table.dtype}")
    if domain_min.shape != (3,) or domain_max.shape != (3,):
        raise ValueError(f"lut_lookup takes a domain of two (3,) tensors, got {tuple(domain_min.shape)} and {tuple(domain_max.shape)}")


def _native(loop: int, codes: Tensor, table: Tensor, domain_min: Tensor, domain_max: Tensor) -> Tensor:
    """The C loop on ``codes`` ``(3, P)`` (copied where a channel's pixels are not contiguous) into a new ``(3, P)``
    tensor: the lattice coordinate ``(x - low) * scale`` with ``scale = (S - 1) / (high - low)``, a product where
    :func:`torch_form` divides (the two agree to a rounding of the coordinate)."""
    size = table.shape[0]
    if codes.stride(-1) != 1:
        codes = codes.contiguous()
    out = torch.empty(codes.shape, dtype=codes.dtype)
    low = domain_min.to(torch.float64)
    scale = ((size - 1) / (domain_max.to(torch.float64) - low)).to(codes.dtype).contiguous()
    low, packed = low.to(codes.dtype).contiguous(), table.contiguous()
    NATIVE.interpolate(loop, codes.data_ptr(), 0, codes.stride(0), out.data_ptr(), 0, out.stride(0), 1, codes.shape[1],
                       low.data_ptr(), scale.data_ptr(), packed.data_ptr(), size, CHUNK_PIXELS, torch.get_num_threads())
    return out


@functools.lru_cache(maxsize=None)
def _warn_once() -> None:
    warnings.warn("torchgrade was installed without its compiled LUT loop (no C compiler worked when it was built): "
                  "CPU LUT lookups run in torch operations, several times slower. Reinstall torchgrade where a C "
                  "compiler works (`pip install --force-reinstall --no-deps torchgrade`, or `make setup`) to build it.",
                  RuntimeWarning, stacklevel=4)


@lut_lookup.register_fake
def _(codes, table, domain_min, domain_max, interpolation, nan_free=False):
    return codes.new_empty(codes.shape)


def _setup_context(ctx, inputs, output) -> None:
    codes, table, domain_min, domain_max, interpolation, nan_free = inputs
    ctx.save_for_backward(codes, table, domain_min, domain_max)
    ctx.interpolation, ctx.nan_free = interpolation, nan_free


def _backward(ctx, grad: Tensor):
    """The gradients of :func:`torch_form` with respect to the codes and the table (recomputed: the C loop keeps no
    intermediate); the domain is a constant."""
    codes, table, domain_min, domain_max = ctx.saved_tensors

    def looked_up(x, entries):
        return torch_form(x, entries, domain_min, domain_max, ctx.interpolation, ctx.nan_free)

    pullback = torch.func.vjp(looked_up, codes, table)[1]
    grad_codes, grad_table = pullback(grad)
    return grad_codes, grad_table, None, None, None, None


lut_lookup.register_autograd(_backward, setup_context=_setup_context)

_EXPORT_RULE = torch.library.Library("torchgrade", "FRAGMENT")
_EXPORT_RULE.impl("lut_lookup", torch_form, "Tracer")
