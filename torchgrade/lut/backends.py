"""The graph forms a LUT is exported in (``tg.onnx.export(..., lut_backend=...)``), each a graph form of the kernels of
:data:`~torchgrade.lut.kernels.KERNELS` where one is declared, else their gathers."""

from __future__ import annotations

from ..base.params import check_choice

__all__ = ["BACKENDS", "LUT_BACKENDS", "backend_named"]

BACKENDS = {"slices": 16, "gather": 16, "volume": 20}
"""Export backends of a LUT and the lowest opset each needs: ``"slices"`` (4-D ``GridSample`` on the table laid out
as its blue slices side by side, where a kernel has that form, else gathers), ``"gather"`` (gathers only) and
``"volume"`` (5-D ``GridSample``, opset 20, which OpenVINO rejects and TensorRT has mis-mapped)."""

LUT_BACKENDS = tuple(BACKENDS)


def backend_named(name: str) -> str:
    """``name``, checked to be one of :data:`BACKENDS`.

    Examples:
        >>> backend_named("gather")
        'gather'
        >>> backend_named("texture")
        Traceback (most recent call last):
        ...
        ValueError: lut_backend must be one of 'slices', 'gather', 'volume', got 'texture'
    """
    check_choice("lut_backend", name, BACKENDS)
    return name
