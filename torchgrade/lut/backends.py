"""The graph forms a LUT is exported in (``tg.onnx.export(..., lut_backend=...)``), each a graph form of the kernels of
:data:`~torchgrade.lut.kernels.KERNELS` where one is declared, else their gathers."""

from __future__ import annotations

import warnings

from ..base.params import check_choice

__all__ = ["BACKENDS", "LUT_BACKENDS", "FORMER_BACKENDS", "backend_named"]

BACKENDS = {"slices": 16, "gather": 16, "volume": 20}
"""Export backends of a LUT and the lowest opset each needs: ``"slices"`` (4-D ``GridSample`` on the table laid out
as its blue slices side by side, where a kernel has that form, else gathers), ``"gather"`` (gathers only) and
``"volume"`` (5-D ``GridSample``, opset 20, which OpenVINO rejects and TensorRT has mis-mapped)."""

LUT_BACKENDS = tuple(BACKENDS)

FORMER_BACKENDS = {"strip": "slices"}
"""Backend names of earlier releases (``"strip"`` also named the CPU's and the ONNX graph's strips of rows), each
taken with a ``DeprecationWarning`` for a release."""


def backend_named(name: str) -> str:
    """The export backend ``name`` means: one of :data:`BACKENDS`, or a former name, with a warning.

    Examples:
        >>> backend_named("gather")
        'gather'
        >>> backend_named("texture")
        Traceback (most recent call last):
        ...
        ValueError: lut_backend must be one of 'slices', 'gather', 'volume', got 'texture'
    """
    if name in FORMER_BACKENDS:
        warnings.warn(f"lut_backend={name!r} is now {FORMER_BACKENDS[name]!r}; the old name goes in the next release",
                      DeprecationWarning, stacklevel=3)
        return FORMER_BACKENDS[name]
    check_choice("lut_backend", name, BACKENDS)
    return name
