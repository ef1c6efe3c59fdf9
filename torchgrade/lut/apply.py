"""The lookup behind :class:`~torchgrade.LUT3D` (:mod:`.layer`): a pixel through the shaper, the lattice and the table, and its compile cache.

A :class:`LUT3D` maps a linear Rec.709 pixel ``x`` to an output colour in five steps::

    s = shaper(x)                                   # torchgrade.lut.shapers: linear, logc, curve
    u = clamp((s - domain_min) / (domain_max - domain_min), 0, 1)      # per channel
    y = interpolate(table, u * (size - 1))          # torchgrade.lut.kernels: trilinear, tetrahedral
    y = decode(y, output_encoding)                  # "linear": y; "srgb": sRGB decoding
    y = clamp(y, *output_range)                     # only for display-referred LUTs

**Output encoding.** A table may store sRGB-encoded outputs (``output_encoding="srgb"``, decoded
after the lookup, sign-preserving): the interpolation error is then spread evenly over display code
values instead of piling up in the shadows.

**Forms.** On the CPU the lattice and interpolation steps are the operator ``torchgrade::lut_lookup``
(:mod:`torchgrade.lut.operator`, :func:`operator_lookup`): the C loop built with the package, sanitize, domain, cell
and interpolation in one vectorised pass per pixel over whole frames on torch's own OpenMP threads
(``benchmarks/bench_lut_cpu.py`` times it against OpenColorIO), with the gradients of its torch form, taken whole by
``torch.compile`` and exported as the torch form's gathers. Elsewhere (off the CPU, ``torch.func`` transforms)
:func:`lookup` runs the torch form: gathers on a planar ``(3, size³)`` table that :meth:`LUT3D.rows` converts once
and caches; off the CPU, without autograd, a frame is one pass of :func:`~torchgrade.lut.kernels.tetrahedral_frame`'s
13 operations where the gather form makes 71 (each a kernel launch on a GPU; ``benchmarks/gpu_proxy.py`` counts
them). ``LUT3D(..., compile=True)`` runs non-finite policy, shaper, index math, gathers, weights, decoding and clamp
as one ``torch.compile``d pass of :func:`lookup` with no temporary buffers (for GPUs; on a CPU the operator is
faster).

Examples:
    >>> import torch
    >>> from torchgrade.lut import LUT3D, identity_table
    >>> lut = LUT3D(identity_table(5))
    >>> lut(torch.full((1, 3, 2, 2), 0.3)).flatten()[:3].tolist()  # doctest: +ELLIPSIS
    [0.3..., 0.3..., 0.3...]
"""

from __future__ import annotations

from typing import Callable, Optional

import torch

from ..base.images import check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import check_choice
from ..color import linear_to_srgb, srgb_to_linear
from ..runtime import untracked
from ..runtime.recording import is_differentiated
from .kernels import KERNELS
from .lattice import planar_table
from .operator import lut_lookup
from .shapers import SHAPERS, lattice_unit, shaper_encode

__all__ = ["OUTPUT_ENCODINGS", "apply_lut", "lookup", "operator_lookup", "runs_operator", "whole_frame_tables",
           "compiled_lookup", "decode_output", "encode_output", "table_output", "check_lookup_arguments"]

OUTPUT_ENCODINGS: tuple[str, ...] = ("linear", "srgb")
"""How table entries are stored: linear values, or sRGB-encoded values decoded after the lookup."""


def decode_output(values: torch.Tensor, encoding: str) -> torch.Tensor:
    """Linear output of interpolated table values: identity, or :func:`torchgrade.color.srgb_to_linear`.

    sRGB decoding is sign-preserving (linear segment below 0) and defined above 1, so any table encodes.

    Examples:
        >>> import torch
        >>> decode_output(torch.tensor([1.0]), "srgb").tolist()
        [1.0]
    """
    return values if encoding == "linear" else srgb_to_linear(values)


def encode_output(values: torch.Tensor, encoding: str) -> torch.Tensor:
    """Table entries of linear outputs: the inverse of :func:`decode_output`.

    Examples:
        >>> import torch
        >>> encode_output(torch.tensor([0.5]), "linear").tolist()
        [0.5]
    """
    return values if encoding == "linear" else linear_to_srgb(values)


def table_output(values: torch.Tensor, output_encoding: str, output_range) -> torch.Tensor:
    """A LUT's output from interpolated table values: :func:`decode_output`, then the clamp to ``output_range`` (if any).

    Examples:
        >>> import torch
        >>> table_output(torch.tensor([1.5]), "linear", (0.0, 1.0)).tolist()
        [1.0]
    """
    y = decode_output(values, output_encoding)
    return y if output_range is None else y.clamp(*output_range)


def check_lookup_arguments(image: torch.Tensor, shaper: str, interpolation: str, output_encoding: str) -> None:
    check_image(image)
    check_choice("interpolation", interpolation, KERNELS)
    check_choice("shaper", shaper, SHAPERS)
    check_choice("output encoding", output_encoding, OUTPUT_ENCODINGS)


def apply_lut(image: torch.Tensor, table: torch.Tensor, shaper: str = "linear", domain_min=0.0, domain_max=1.0,
              interpolation: str = "tetrahedral", output_range=None, curve: Optional[torch.Tensor] = None,
              curve_range=(0.0, 1.0), output_encoding: str = "linear") -> torch.Tensor:
    """Apply a 3D LUT to a linear image ``(..., 3, H, W)``; see the module docstring for the steps.

    Non-finite pixels follow the library policy (:func:`torchgrade.base.images.sanitize`) before the
    shaper; inputs outside the domain clamp to it. Differentiable with respect to the image and the
    table; float16/bfloat16 are computed in float32.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table
        >>> apply_lut(torch.full((1, 3, 1, 1), 2.0), identity_table(3)).flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    check_lookup_arguments(image, shaper, interpolation, output_encoding)
    table = table.to(working_dtype(image).dtype)
    settings = (shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding)
    if runs_operator(image, table):
        return operator_lookup(image, table, *settings)
    rows, size = planar_table(table), table.shape[0]
    steps = KERNELS[interpolation].whole_frame.tables(rows, size) if whole_frame_tables(image, rows, size, interpolation) else None
    return lookup(image, rows, size, *settings, tables=steps)


def lookup(image, rows, size: int, shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding,
           tables: Optional[torch.Tensor] = None, nan_free: bool = False) -> torch.Tensor:
    """:func:`apply_lut` on a planar table ``rows`` ``(3, size³)`` already in the image's working dtype.

    One pass per pixel from input to output: non-finite policy, shaper, lattice coordinates,
    interpolation, output decoding and clamp. Arguments are not checked (see :func:`apply_lut`);
    this is the function ``LUT3D(..., compile=True)`` compiles. With the whole-frame form's ``tables``
    (:attr:`EagerForm.tables <torchgrade.lut.kernels.EagerForm>` of ``rows``, where :func:`whole_frame_tables`) the
    interpolation is that form. ``nan_free``: ``image`` holds no NaN (:func:`~torchgrade.base.images.sanitize`).

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table
        >>> from torchgrade.lut.lattice import planar_table
        >>> rows = planar_table(identity_table(2))
        >>> x = torch.full((1, 3, 1, 1), 0.5)
        >>> lookup(x, rows, 2, "linear", 0.0, 1.0, "trilinear", None, None, (0.0, 1.0), "linear").flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    x = sanitize(working_dtype(image), nan_free=nan_free).movedim(-3, 0)  # (3, ..., H, W): a view
    coords = lattice_unit(x.reshape(3, -1), shaper, domain_min, domain_max, curve, curve_range) * (size - 1)
    kernel = KERNELS[interpolation]
    values = kernel(coords, rows, size) if tables is None else kernel.whole_frame.frame(coords, tables, size)
    y = table_output(values, output_encoding, output_range)
    return to_input_dtype(y.reshape(x.shape).movedim(0, -3), image)


def operator_lookup(image, table, shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range,
                    output_encoding, nan_free: bool = False) -> torch.Tensor:
    """:func:`lookup` through the operator :func:`~torchgrade.lut.operator.lut_lookup` on the LUT's own ``table``
    ``(S, S, S, 3)`` in the image's working dtype: the image's planes go to the operator as they are with a linear
    shaper (the operator applies the non-finite policy itself), else the shaper's codes of the sanitized image; the
    output decoding and clamp follow. Differentiable (the operator's gradients), compiled whole by ``torch.compile``,
    and exported as :func:`lookup`'s gathers.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table
        >>> x = torch.full((1, 3, 1, 1), 0.5)
        >>> y = operator_lookup(x, identity_table(2), "linear", 0.0, 1.0, "trilinear", None, None, (0.0, 1.0), "srgb")
        >>> [round(v, 6) for v in y.flatten().tolist()]  # the entries decoded from sRGB: ((0.5 + 0.055) / 1.055)^2.4
        [0.214041, 0.214041, 0.214041]
    """
    x = working_dtype(image).movedim(-3, 0)  # (3, ..., H, W): a view
    codes = x.reshape(3, -1)  # a view for one image
    if shaper != "linear":
        codes = shaper_encode(sanitize(codes, nan_free=nan_free), shaper, curve, curve_range)
    low, high = (_channel_triple(bound, x.dtype) for bound in (domain_min, domain_max))
    values = lut_lookup(codes, table, low, high, interpolation, nan_free or shaper != "linear")
    y = table_output(values, output_encoding, output_range)
    return to_input_dtype(y.reshape(x.shape).movedim(0, -3), image)


def _channel_triple(bound, dtype: torch.dtype) -> torch.Tensor:
    """A domain bound, a number or an RGB triple, as the operator takes it: ``(3,)`` (a LUT's own bounds as they are)."""
    bound = bound if isinstance(bound, torch.Tensor) else torch.tensor(bound, dtype=dtype)
    return bound if bound.shape == (3,) else bound.reshape(-1).expand(3)


def runs_operator(image: torch.Tensor, table: torch.Tensor) -> bool:
    """Whether a lookup of ``image`` goes through the operator (:func:`operator_lookup`): on the CPU, its kernel's
    device, outside ``torch.func`` transforms and forward-mode derivatives (the operator has reverse-mode gradients
    only). Elsewhere :func:`lookup` runs.

    Examples:
        >>> import torch
        >>> runs_operator(torch.zeros(1, 3, 1, 1), torch.zeros(2, 2, 2, 3)), runs_operator(torch.zeros(1, 3, 1, 1, device="meta"), torch.zeros(2, 2, 2, 3))
        (True, False)
    """
    return image.device.type == "cpu" and not (is_differentiated(image) or is_differentiated(table))


def whole_frame_tables(image: torch.Tensor, rows: torch.Tensor, size: int, interpolation: str) -> bool:
    """Whether :func:`lookup` of ``image`` off the CPU takes the interpolation's whole-frame form
    (:class:`~torchgrade.lut.kernels.EagerForm`): it has one for this lattice, and nothing records the lookup
    (autograd, tracing, compiling and ``torch.func`` run the gather form).

    Examples:
        >>> import torch
        >>> rows = torch.zeros(3, 8)
        >>> whole_frame_tables(torch.zeros(1, 3, 1, 1), rows, 2, "tetrahedral"), whole_frame_tables(torch.zeros(1, 3, 1, 1), rows, 2, "trilinear")
        (True, False)
    """
    eager = KERNELS[interpolation].eager
    return eager is not None and size <= eager.max_size and untracked(image, rows)


_COMPILED = None


def compiled_lookup() -> Callable:
    """:func:`lookup` through ``torch.compile`` (created once, on first use; pixel counts become dynamic
    after the first recompile, so new frame sizes do not compile again).

    Examples:
        >>> compiled_lookup() is compiled_lookup()
        True
    """
    global _COMPILED
    if _COMPILED is None:
        _COMPILED = torch.compile(lookup)
    return _COMPILED
