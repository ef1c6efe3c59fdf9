"""``LUT3D``: a baked 3D LUT as a stage, and ``LUTLookup``, its ONNX export form."""

from __future__ import annotations

import copy
import warnings
from typing import Optional

import torch
from torch import nn

from ..base.images import HALF_MAX, sanitize, working_dtype
from ..base.params import check_choice
from ..base.controls import Control, in_state_check
from ..base.stage import Stage
from .backends import backend_named
from .kernels import KERNELS
from .lattice import MAX_CODE, check_size, checked_domain, planar_table
from .apply import (
    OUTPUT_ENCODINGS,
    check_lookup_arguments,
    compiled_lookup,
    decode_output,
    encode_output,
    lookup,
    operator_lookup,
    runs_operator,
    table_output,
    whole_frame_tables,
)
from .report import ErrorReport
from .shapers import SHAPERS, lattice_unit

__all__ = ["LUT3D", "LUTLookup", "entry_bound"]


def _pair(value, name: str):
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (low, high) pair of numbers, got {value!r}") from None
    if not low < high:
        raise ValueError(f"{name} must have low < high, got {value!r}")
    return low, high


class LUT3D(Stage):
    """A baked 3D LUT: ``LUT3D(table, shaper="linear", interpolation="tetrahedral")(image)``.

    The table, the lattice domain and a curve shaper's curve are tensors (buffers, or the table a
    parameter); the settings below are controls, checked on assignment and listed by ``to_config``.

    Args:
        table: ``(S, S, S, 3)`` indexed ``[b, g, r, channel]`` (red fastest), ``2 <= S <= 256``.
        shaper: a name in :data:`~torchgrade.lut.SHAPERS` (``"curve"`` needs ``curve`` ``(n, 3)`` and ``curve_range``).
        domain: ``(min, max)`` of the lattice in shaper code values, numbers or RGB triples;
            default the shaper's ``default_domain``.
        output_range: ``(low, high)`` clamp applied after the lookup, or ``None``.
        output_encoding: ``"linear"`` (entries are linear outputs) or ``"srgb"`` (entries are
            sRGB-encoded and decoded after the lookup; :meth:`linear_table` gives linear entries).
        interpolation: how the lattice is interpolated, a name in :data:`~torchgrade.lut.KERNELS` (``"tetrahedral"``,
            ``"trilinear"``); a control, so a look, its config and its ONNX export carry it. ``forward(image,
            interpolation)`` may still name another for one call.
        learnable: hold the table as an ``nn.Parameter`` (fit a LUT by gradient descent).
        compile: run the lookup through ``torch.compile``: one fused pass over the pixels, faster
            than eager, but the first call per interpolation and dtype compiles (seconds; see
            benchmarks/results/lut.md).

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> lut = LUT3D(identity_table(3), shaper="logc")
        >>> lut.to_config(), lut.is_identity
        ({'shaper': 'logc'}, False)
    """

    per_pixel = True

    # the controls, buffers and report ``__init__`` sets, as a type checker reads them (nn.Module's own attribute
    # lookup types every other attribute as a tensor or a module)
    shaper: str
    output_range: Optional[tuple[float, float]]
    curve_range: tuple[float, float]
    output_encoding: str
    compile: bool  # type: ignore[assignment]  # the control, which hides nn.Module.compile on a LUT3D
    interpolation: str
    table: torch.Tensor
    domain_min: torch.Tensor
    domain_max: torch.Tensor
    curve: Optional[torch.Tensor]
    error_report: Optional[ErrorReport]

    controls = {
        "shaper": Control("linear", tuple(SHAPERS)),
        "output_range": Control(None),
        "curve_range": Control((0.0, 1.0)),
        "output_encoding": Control("linear", OUTPUT_ENCODINGS),
        "compile": Control(False),
        "interpolation": Control("tetrahedral", tuple(KERNELS)),
    }

    def __init__(self, table: torch.Tensor, shaper: str = "linear", domain=None, output_range=None,
                 curve: Optional[torch.Tensor] = None, curve_range=(0.0, 1.0), learnable: bool = False,
                 compile: bool = False, output_encoding: str = "linear", interpolation: str = "tetrahedral"):
        super().__init__()
        check_choice("shaper", shaper, SHAPERS)
        check_choice("output encoding", output_encoding, OUTPUT_ENCODINGS)
        _check_table(table, output_encoding)
        if SHAPERS[shaper].takes_curve != (curve is not None):
            raise ValueError(f"the {shaper!r} shaper {'needs' if SHAPERS[shaper].takes_curve else 'takes no'} curve=(n, 3) table")
        self.size = table.shape[0]
        if learnable:
            self.table = nn.Parameter(table.detach().clone())
        else:
            self.register_buffer("table", table)
        low, high = checked_domain(domain if domain is not None else SHAPERS[shaper].default_domain)
        self.register_buffer("domain_min", low)
        self.register_buffer("domain_max", high)
        self.register_buffer("curve", None if curve is None else _check_curve(curve))
        self._rows_cache: tuple = (None, None, None)
        self._tables_cache: tuple = (None, None, None)  # (rows, interpolation, the whole-frame form's tables)
        self.error_report = None  # set by bake_lut: a torchgrade.lut.ErrorReport
        self.init_controls(shaper=shaper, output_range=output_range, curve_range=curve_range,
                           output_encoding=output_encoding, compile=bool(compile), interpolation=interpolation)

    def check_control(self, name: str, value):
        if name == "output_range":
            return None if value is None else _pair(value, name)
        if name == "curve_range":
            return _pair(value, name)
        return value

    def check_learnable(self) -> None:
        """Also check a learnable table, which an optimiser may move to NaN or Inf: once per change of the table,
        without waiting for a GPU (:class:`~torchgrade.runtime.DeferredCheck`)."""
        super().check_learnable()
        if isinstance(self.table, nn.Parameter):
            bound = entry_bound(self.output_encoding)
            self.deferred_check()({"table": self.table}, lambda name, extremes: _check_extremes(extremes, bound), summary=_extremes)

    def check_state(self) -> None:
        """Also the table, the domain and a shaper's curve, as the constructor checks them (a saved LUT is untrusted);
        a learnable table is checked at every forward instead, and nothing on ``meta`` has values to check."""
        super().check_state()
        if in_state_check(self.table):
            _check_table(self.table, self.output_encoding)
        if self.size != self.table.shape[0]:
            raise ValueError(f"a LUT of size {self.size} holds a table of {tuple(self.table.shape)}: the two disagree")
        if in_state_check(self.domain_min):
            checked_domain((self.domain_min, self.domain_max))
        if SHAPERS[self.shaper].takes_curve != (self.curve is not None):
            raise ValueError(f"the {self.shaper!r} shaper {'needs' if self.curve is None else 'takes no'} curve=(n, 3) table")
        if self.curve is not None:
            _check_curve(self.curve)

    @property
    def is_identity(self) -> bool:
        """Never: a table is not checked for being the identity, so a LUT always runs."""
        return False

    def forward(self, image: torch.Tensor, interpolation: Optional[str] = None, *, nan_free: bool = False) -> torch.Tensor:
        interpolation = interpolation or self.interpolation
        check_lookup_arguments(image, self.shaper, interpolation, self.output_encoding)
        dtype = working_dtype(image).dtype
        settings = (self.shaper, self.domain_min, self.domain_max, interpolation, self.output_range, self.curve,
                    self.curve_range, self.output_encoding)
        if self.compile:
            try:
                return compiled_lookup()(image, self.rows(dtype), self.size, *settings)
            except Exception as error:  # no C++ compiler, unsupported device, ...: the eager path always works
                warnings.warn(f"LUT3D(compile=True) fell back to eager: torch.compile failed with {error!r}", RuntimeWarning,
                              stacklevel=4)
                self.compile = False
        if runs_operator(image, self.table):
            return operator_lookup(image, self.table.to(dtype), *settings, nan_free=nan_free)
        rows = self.rows(dtype)
        return lookup(image, rows, self.size, *settings, tables=self._whole_frame_tables(image, rows, interpolation), nan_free=nan_free)

    def rows(self, dtype: torch.dtype) -> torch.Tensor:
        """The table as planar rows ``(3, S³)`` in ``dtype`` (:func:`~torchgrade.lut.planar_table`), what the kernels read.

        Cached until the table is replaced, moved or modified in place; computed on every call while
        gradients flow to the table, so autograd sees the conversion, and while compiling, so the graph holds it
        (the cache's key, the table's address, is no value a graph can hold).
        """
        table = self.table
        if (table.requires_grad and torch.is_grad_enabled()) or torch.compiler.is_compiling():
            return planar_table(table.to(dtype))
        key = (table.data_ptr(), table._version, dtype)
        cached_table, cached_key, rows = self._rows_cache
        if cached_table is not table or cached_key != key:
            rows = planar_table(table.detach().to(dtype))
            self._rows_cache = (table, key, rows)  # holding the table keeps its address from being reused
        return rows

    def _apply(self, fn, *args, **kwargs):
        """Moves and casts drop the whole-frame form's cached tables: they are derived from the table where it was."""
        self._tables_cache = (None, None, None)
        return super()._apply(fn, *args, **kwargs)

    def _whole_frame_tables(self, image: torch.Tensor, rows: torch.Tensor, interpolation: str) -> Optional[torch.Tensor]:
        """The whole-frame form's tables of ``rows`` (:meth:`rows`), cached with them; ``None`` where the lookup of
        ``image`` runs the gather form (:func:`~torchgrade.lut.apply.whole_frame_tables`)."""
        if not whole_frame_tables(image, rows, self.size, interpolation):
            return None
        cached_rows, cached_interpolation, tables = self._tables_cache
        if cached_rows is not rows or cached_interpolation != interpolation:
            with torch.no_grad():
                tables = KERNELS[interpolation].whole_frame.tables(rows, self.size)
            self._tables_cache = (rows, interpolation, tables)
        return tables

    def looked_up_with(self, interpolation: Optional[str]) -> "LUT3D":
        """This LUT, or with another ``interpolation`` a shallow copy looked up with it: the copy shares this LUT's table
        (learnable or not) and this LUT keeps its own interpolation; ``ValueError`` for an unknown interpolation.

        Examples:
            >>> from torchgrade.lut import identity_table
            >>> lut = LUT3D(identity_table(3))
            >>> trilinear = lut.looked_up_with("trilinear")
            >>> trilinear.interpolation, lut.interpolation, trilinear.table is lut.table
            ('trilinear', 'tetrahedral', True)
        """
        if interpolation is None or interpolation == self.interpolation:
            return self
        looked_up = copy.copy(self)
        looked_up.interpolation = interpolation  # the control's check refuses an unknown name
        return looked_up

    def linear_table(self) -> torch.Tensor:
        """The table with linear output values (decoded by ``output_encoding``), as a ``.cube`` file holds it."""
        return decode_output(self.table, self.output_encoding)

    def export_form(self, interpolation: Optional[str] = None, backend: str = "slices") -> nn.Module:
        """The module an ONNX export traces for this LUT looked up with ``interpolation`` (its own by default), in
        ``backend``'s graph form."""
        interpolation = interpolation or self.interpolation
        check_choice("interpolation", interpolation, KERNELS)
        return LUTLookup(self, interpolation, backend_named(backend))

    def extra_repr(self) -> str:
        domain = f"domain=({_short(self.domain_min)}, {_short(self.domain_max)})"
        clamp = f", output_range={self.output_range}" if self.output_range else ""
        encoding = f", output_encoding={self.output_encoding!r}" if self.output_encoding != "linear" else ""
        interpolation = f", interpolation={self.interpolation!r}" if self.interpolation != "tetrahedral" else ""
        return f"size={self.size}, shaper={self.shaper!r}, {domain}{clamp}{encoding}{interpolation}"


class LUTLookup(nn.Module):
    """A :class:`LUT3D` lookup with a fixed interpolation and graph form: what an ONNX export traces.

    With a grid form for ``backend`` (:meth:`~torchgrade.lut.Kernel.graph_form`) the lattice
    coordinates go to ``grid_sample``; otherwise the LUT's own gather lookup is traced.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table
        >>> lookup = LUT3D(identity_table(3)).export_form("trilinear", "slices")
        >>> lookup(torch.full((1, 3, 1, 1), 0.5)).flatten().tolist()
        [0.5, 0.5, 0.5]
    """

    per_pixel = True

    def __init__(self, lut: LUT3D, interpolation: str, backend: str):
        super().__init__()
        self.lut = lut
        self.interpolation = interpolation
        self.grid = KERNELS[interpolation].graph_form(backend)

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        if self.grid is None:
            return self.lut(image, self.interpolation, nan_free=nan_free)
        lut = self.lut
        x = sanitize(image, nan_free=nan_free)
        n, _, height, width = x.shape
        points = x.transpose(0, 1).reshape(3, -1)
        unit = lattice_unit(points, lut.shaper, lut.domain_min, lut.domain_max, lut.curve, lut.curve_range)
        unit = unit.reshape(3, n, height, width).transpose(0, 1)
        y = self.grid(unit, lut.table.to(x.dtype))
        return table_output(y, lut.output_encoding, lut.output_range)


def _extremes(table: torch.Tensor) -> torch.Tensor:
    """``(max, min)`` of a table: NaN when it holds a NaN, infinite when it holds an infinity."""
    return torch.stack((table.amax(), table.amin()))


def entry_bound(output_encoding: str) -> float:
    """The largest magnitude a table entry may have: ±65504, the non-finite policy's bound, as the entries store it
    (sRGB-encoded entries: the code of 65504, about 107.1, which decodes to 65504).

    Examples:
        >>> entry_bound("linear"), round(entry_bound("srgb"), 3)
        (65504.0, 107.105)
    """
    return _ENTRY_BOUNDS[output_encoding]


_ENTRY_BOUNDS = {encoding: float(encode_output(torch.tensor(HALF_MAX, dtype=torch.float64), encoding)) for encoding in OUTPUT_ENCODINGS}


def _check_extremes(extremes: torch.Tensor, bound: float = HALF_MAX) -> None:
    """Every entry finite and within ``bound`` (:func:`entry_bound`): interpolation weights lie in [0, 1] and sum to 1,
    so a lookup then stays within ±65504 and its gradients finite for every input and interpolation (entries of
    ±3.4e38, finite in float32, made +Inf through tetrahedral's differences and NaN through trilinear's)."""
    if not bool(torch.isfinite(extremes).all()):
        raise ValueError("LUT table must be finite: it has NaN or infinite entries")
    if not bool((extremes.abs() <= bound).all()):
        raise ValueError(f"LUT table entries must lie in [-{bound:g}, {bound:g}], got entries from "
                         f"{extremes[1].item():.6g} to {extremes[0].item():.6g}")


def _check_table(table, output_encoding: str = "linear") -> None:
    if not isinstance(table, torch.Tensor) or not table.is_floating_point():
        raise TypeError(f"LUT table must be a floating-point tensor, got {getattr(table, 'dtype', type(table).__name__)}")
    size = table.shape[0] if table.dim() == 4 else None
    if table.dim() != 4 or table.shape != (size, size, size, 3):
        raise ValueError(f"LUT table must have shape (S, S, S, 3), got {tuple(table.shape)}")
    check_size(size)
    # amax and amin propagate NaN and reach ±Inf, without isfinite's table-sized temporaries (336 MiB at 256³).
    _check_extremes(_extremes(table.detach()), entry_bound(output_encoding))


def _check_curve(curve: torch.Tensor) -> torch.Tensor:
    if not isinstance(curve, torch.Tensor) or not curve.is_floating_point():
        raise TypeError(f"shaper curve must be a floating-point tensor, got {getattr(curve, 'dtype', type(curve).__name__)}")
    if curve.dim() != 2 or curve.shape[1] != 3 or curve.shape[0] < 2:
        raise ValueError(f"shaper curve must have shape (n >= 2, 3), got {tuple(curve.shape)}")
    high, low = _extremes(curve.detach()).tolist()
    if not (abs(low) <= MAX_CODE and abs(high) <= MAX_CODE):  # NaN fails both
        raise ValueError(f"shaper curve entries must be finite and within ±{MAX_CODE:g}, got {low} to {high}")
    return curve


def _short(t: torch.Tensor):
    values = [round(v, 6) for v in t.tolist()]
    return values[0] if len(set(values)) == 1 else tuple(values)
