"""Whether anything records how tensors are used: tracing, compiling, exporting, autograd.

Eager-only forms (computed in place, strips, shortcuts that read a value) run only where nothing records.
"""

from __future__ import annotations

import sys

import torch
from torch.autograd import forward_ad

__all__ = ["is_tracing", "is_exporting", "is_differentiated", "untracked"]


def is_tracing() -> bool:
    """True while tracing, compiling or exporting to ONNX: data-dependent checks and shortcuts are skipped.

    Examples:
        >>> is_tracing()
        False
    """
    return torch.jit.is_tracing() or torch.compiler.is_compiling() or _exporting_eagerly()


def is_exporting() -> bool:
    """``torch.onnx.is_in_onnx_export()``, without loading ``torch.onnx`` where nothing has: an export loads it first,
    and ONNX's exporter takes longer to import than torchgrade (``benchmarks/results/import.md``; ``import torchgrade``, whose constants are computed with the
    library's functions, and the first frame would pay it). While compiling it is asked directly: Dynamo folds the
    call, and would trace the lookup in ``sys.modules``.

    Examples:
        >>> is_exporting()
        False
    """
    if torch.compiler.is_compiling():
        return torch.onnx.is_in_onnx_export()
    return _exporting_eagerly()


def _exporting_eagerly() -> bool:
    """:func:`is_exporting` outside a compiler: asked of ``torch.onnx`` only where it is loaded."""
    onnx = sys.modules.get("torch.onnx")
    return onnx is not None and onnx.is_in_onnx_export()


def untracked(*tensors) -> bool:
    """True when nothing records how ``tensors`` are used: no autograd (grad disabled, or none requires grad), no
    ``torch.func`` transform or forward-mode derivative (:func:`is_differentiated`), no tracing, compiling or
    exporting. Eager forms that compute in place or skip a guard need this.

    Examples:
        >>> x = torch.ones(2)
        >>> untracked(x), untracked(x.requires_grad_())
        (True, False)
        >>> with torch.no_grad():
        ...     untracked(x)
        True
    """
    given = [t for t in tensors if isinstance(t, torch.Tensor)]
    recorded = torch.is_grad_enabled() and any(t.requires_grad for t in given)
    return not recorded and not any(map(is_differentiated, given)) and not is_tracing()


def is_differentiated(value: torch.Tensor) -> bool:
    """Whether ``value`` carries a forward-mode derivative that ``requires_grad`` does not show: a dual tensor of
    ``torch.autograd.forward_ad`` or of ``torch.func.jvp`` and ``jacfwd`` (inside ``torch.func.grad`` a tensor
    ``requires_grad``). A guard skipped, or a form computed in place, would lose it.

    Examples:
        >>> from torch.autograd import forward_ad
        >>> with forward_ad.dual_level():
        ...     dual = forward_ad.make_dual(torch.tensor(0.0), torch.tensor(1.0))
        ...     is_differentiated(torch.tensor(0.0)), is_differentiated(dual)
        (False, True)
    """
    return forward_ad.unpack_dual(value).tangent is not None
