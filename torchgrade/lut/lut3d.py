"""``LUT3D``: a baked 3D LUT as a stage, its lookup, its compile cache and its export form.

A :class:`LUT3D` maps a linear Rec.709 pixel ``x`` to an output colour in five steps::

    s = shaper(x)                                   # torchgrade.lut.shapers: linear, logc, curve
    u = clamp((s - domain_min) / (domain_max - domain_min), 0, 1)      # per channel
    y = interpolate(table, u * (size - 1))          # torchgrade.lut.kernels: trilinear, tetrahedral
    y = decode(y, output_encoding)                  # "linear": y; "srgb": sRGB decoding
    y = clamp(y, *output_range)                     # only for display-referred LUTs

**Output encoding.** A table may store sRGB-encoded outputs (``output_encoding="srgb"``, decoded
after the lookup, sign-preserving): the interpolation error is then spread evenly over display code
values instead of piling up in the shadows.

**Speed.** The lookup is gather-based on a planar ``(3, size³)`` table that :meth:`LUT3D.rows`
converts once and caches. Every step is per pixel, so ``LUT3D(..., compile=True)`` runs non-finite
policy, shaper, index math, gathers, weights, decoding and clamp as one ``torch.compile``d pass
with no temporary buffers. The eager default on the CPU (:func:`chunked_lookup`) makes one pass per
operation over runs of :data:`~torchgrade.runtime.LOOKUP_CHUNK` pixels, each run on one thread, as
OpenColorIO's CPU processor does: the temporaries stay in cache, and no operation waits at a thread
barrier (on a loaded machine each barrier can wait for a descheduled thread; benchmarks/results/lut.md
measured 131× OpenColorIO with two threads). On many cores the runs are spread over worker threads
(:class:`~torchgrade.runtime.ExecutionPolicy`); on other devices the frame is one pass. Without autograd, tetrahedral runs its eager form
(:class:`~torchgrade.lut.kernels.TetrahedralRuns`): 15 in-place operations a run into buffers
allocated once per call, gathering from value-and-step tables derived once per LUT; 12 one-float
gathers a pixel are about half its time. benchmarks/bench_lut.py measures both against OpenColorIO.

Examples:
    >>> import torch
    >>> from torchgrade.lut import identity_table
    >>> lut = LUT3D(identity_table(5))
    >>> lut(torch.full((1, 3, 2, 2), 0.3)).flatten()[:3].tolist()  # doctest: +ELLIPSIS
    [0.3..., 0.3..., 0.3...]
"""

from __future__ import annotations

import warnings
from typing import Callable, Optional

import torch
from torch import nn

from ..color import linear_to_srgb, srgb_to_linear
from ..core import HALF_MAX, check_choice, check_image, is_tracing, one_thread, sanitize, to_input_dtype, working_dtype
from ..runtime import LOOKUP_CHUNK, policy_for, run_pieces
from ..stage import Control, Stage, in_state_check
from .kernels import BACKENDS, KERNELS
from .lattice import check_size, checked_domain, planar_table
from .shapers import SHAPERS, lattice_unit, shaper_encode

__all__ = ["LUT3D", "LUTLookup", "OUTPUT_ENCODINGS", "LOOKUP_CHUNK", "apply_lut", "lookup", "chunked_lookup", "compiled_lookup",
           "decode_output", "encode_output", "table_output", "entry_bound"]

OUTPUT_ENCODINGS = ("linear", "srgb")
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


def _check_arguments(image: torch.Tensor, shaper: str, interpolation: str, output_encoding: str) -> None:
    check_image(image)
    check_choice("interpolation", interpolation, KERNELS)
    check_choice("shaper", shaper, SHAPERS)
    check_choice("output encoding", output_encoding, OUTPUT_ENCODINGS)


def apply_lut(image: torch.Tensor, table: torch.Tensor, shaper: str = "linear", domain_min=0.0, domain_max=1.0,
              interpolation: str = "tetrahedral", output_range=None, curve: Optional[torch.Tensor] = None,
              curve_range=(0.0, 1.0), output_encoding: str = "linear") -> torch.Tensor:
    """Apply a 3D LUT to a linear image ``(..., 3, H, W)``; see the module docstring for the steps.

    Non-finite pixels follow the library policy (:func:`torchgrade.core.sanitize`) before the
    shaper; inputs outside the domain clamp to it. Differentiable with respect to the image and the
    table; float16/bfloat16 are computed in float32.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table
        >>> apply_lut(torch.full((1, 3, 1, 1), 2.0), identity_table(3)).flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    _check_arguments(image, shaper, interpolation, output_encoding)
    rows = planar_table(table.to(working_dtype(image).dtype))
    return chunked_lookup(image, rows, table.shape[0], shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding)


def lookup(image, rows, size: int, shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding) -> torch.Tensor:
    """:func:`apply_lut` on a planar table ``rows`` ``(3, size³)`` already in the image's working dtype.

    One pass per pixel from input to output: non-finite policy, shaper, lattice coordinates,
    interpolation, output decoding and clamp. Arguments are not checked (see :func:`apply_lut`);
    this is the function ``LUT3D(..., compile=True)`` compiles.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table, planar_table
        >>> rows = planar_table(identity_table(2))
        >>> x = torch.full((1, 3, 1, 1), 0.5)
        >>> lookup(x, rows, 2, "linear", 0.0, 1.0, "trilinear", None, None, (0.0, 1.0), "linear").flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    x = sanitize(working_dtype(image)).movedim(-3, 0)  # (3, ..., H, W): a view
    unit = lattice_unit(x.reshape(3, -1), shaper, domain_min, domain_max, curve, curve_range)
    y = table_output(KERNELS[interpolation](unit * (size - 1), rows, size), output_encoding, output_range)
    return to_input_dtype(y.reshape(x.shape).movedim(0, -3), image)


def chunked_lookup(image, rows, size: int, *settings, pixels: Optional[int] = None, tables=None) -> torch.Tensor:
    """:func:`lookup` (same arguments after ``size``) over ``pixels``-sized runs of each CPU image's pixels, each on one thread.

    Every step is per pixel, so the runs give the one-pass result. Where the interpolation has an
    eager form (:class:`~torchgrade.lut.EagerForm`: tetrahedral up to 65³) the runs go through it,
    into buffers allocated once per call, from its ``tables`` (derived from ``rows`` when not given;
    :class:`LUT3D` caches them): the same values to float rounding. While gradients flow to the image
    or the table (autograd keeps every temporary anyway), off the CPU, and while tracing (an export
    records one pass), the whole image is one pass of :func:`lookup`.

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table, planar_table
        >>> x = torch.rand(2, 3, 4, 5)
        >>> args = (planar_table(torch.rand(3, 3, 3, 3)), 3, "linear", 0.0, 1.0, "trilinear", None, None, (0.0, 1.0), "linear")
        >>> torch.equal(chunked_lookup(x, *args, pixels=7), lookup(x, *args))
        True
    """
    height, width = image.shape[-2:]
    if not _in_runs(image, rows):
        return lookup(image, rows, size, *settings)
    policy = policy_for(image.device)
    pixels = pixels or policy.lookup_chunk
    planes = image.reshape(-1, 3, height * width)
    result = torch.empty(planes.shape, dtype=image.dtype)
    eager = KERNELS[settings[3]].eager
    if eager is not None and size <= eager.max_size and tables is None:
        tables = eager.tables(rows, size)

    def share(span: tuple) -> None:
        begin, end = span
        if eager is None or size > eager.max_size:
            for frame, out in zip(planes, result):
                for start in range(begin, end, pixels):
                    stop = min(start + pixels, end)
                    run = frame[:, start:stop].unsqueeze(-1)  # (3, run, 1): an image of one column
                    out[:, start:stop] = lookup(run, rows, size, *settings).squeeze(-1)
        else:
            _eager_lookup(planes[..., begin:end], result[..., begin:end], rows, size, settings, pixels, eager, tables)

    shares = _shares(height * width, pixels, policy.workers)
    if policy.workers > 1:
        run_pieces(share, shares, policy.workers)
    else:
        with one_thread():
            share(shares[0])
    return result.reshape(image.shape)


def _shares(count: int, pixels: int, workers: int) -> list:
    """``[(begin, end), ...]``: ``count`` pixels cut into at most ``workers`` contiguous shares of whole runs.

    Examples:
        >>> _shares(10, 3, 2), _shares(10, 3, 1)
        ([(0, 6), (6, 10)], [(0, 10)])
    """
    runs = -(-count // pixels)
    per_share = -(-runs // max(1, workers)) * pixels
    return [(begin, min(begin + per_share, count)) for begin in range(0, count, per_share)]


def _in_runs(image: torch.Tensor, rows: torch.Tensor) -> bool:
    """Whether :func:`chunked_lookup` splits the image into runs: where the device's policy asks (the CPU),
    untraced, no gradient flowing."""
    grad = torch.is_grad_enabled() and (image.requires_grad or rows.requires_grad)
    return not grad and policy_for(image.device).lookup_chunk is not None and not is_tracing()


def _eager_lookup(planes, result, rows, size, settings, pixels, eager, tables) -> None:
    """:func:`chunked_lookup` through an eager form: ``planes`` ``(N, 3, P)`` into ``result``, runs of ``pixels``."""
    shaper, domain_min, domain_max, _, output_range, curve, curve_range, output_encoding = settings
    run = max(1, min(pixels, planes.shape[-1]))
    runs = eager.runs(eager.tables(rows, size) if tables is None else tables, size, run)
    direct = output_encoding == "linear" and output_range is None and result.dtype == rows.dtype
    values = None if direct else torch.empty(3 * run, dtype=rows.dtype)
    lattice = _LatticeCoordinates(rows.dtype, size, shaper, domain_min, domain_max, curve, curve_range)
    for frame, out in zip(planes, result):
        for start in range(0, frame.shape[-1], run):
            x = frame[:, start:start + run]
            n = x.shape[-1]
            lattice(x, runs.coords(n))
            if direct:
                runs(out[:, start:start + n])
            else:
                y = runs(values[:3 * n].view(3, n))
                out[:, start:start + n] = to_input_dtype(table_output(y, output_encoding, output_range), out)


class _LatticeCoordinates:
    """``lattice_unit(sanitize(x)) * (size - 1)`` of ``(3, n)`` runs written into a buffer: the operations of
    :func:`lookup`, bit for bit, less those that are exact identities for the LUT's domain."""

    def __init__(self, dtype, size, shaper, domain_min, domain_max, curve, curve_range):
        def column(value):  # as lattice_unit forms it
            return torch.as_tensor(value, dtype=dtype).reshape(-1, 1).expand(3, 1)

        self.low, high = column(domain_min), column(domain_max)
        self.span = high - self.low
        self.size, self.dtype, self.shaper, self.curve, self.curve_range = size, dtype, shaper, curve, curve_range
        self.shift = bool((self.low != 0).any())  # x - 0 and x / 1 are exact: skipped
        self.scale = bool((self.span != 1).any())
        # A linear shaper's domain inside ±HALF_MAX clamps whatever sanitize's clamp to ±HALF_MAX would,
        # to the same ends; nan_to_num then does the rest of sanitize (NaN -> 0, ±Inf -> ±HALF_MAX).
        bounded = bool((self.low >= -HALF_MAX).all()) and bool((high <= HALF_MAX).all())
        self.unclamped = shaper == "linear" and bounded

    def __call__(self, x: torch.Tensor, buffer: torch.Tensor) -> torch.Tensor:
        if x.dtype != self.dtype:
            x = buffer.copy_(x)
        if self.unclamped:
            codes = torch.nan_to_num(x, nan=0.0, posinf=HALF_MAX, neginf=-HALF_MAX, out=buffer)
        else:
            torch.clamp(x, -HALF_MAX, HALF_MAX, out=buffer).nan_to_num_(nan=0.0)
            codes = shaper_encode(buffer, self.shaper, self.curve, self.curve_range)
        if self.shift or codes is not buffer:
            codes = torch.sub(codes, self.low, out=buffer)
        if self.scale:
            codes.div_(self.span)
        return codes.clamp_(0.0, 1.0).mul_(self.size - 1)


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
        self._rows_cache = (None, None, None)
        self._tables_cache = (None, None, None)  # (rows, interpolation, the eager form's tables)
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
        if isinstance(self.table, nn.Parameter) and not is_tracing():
            bound = entry_bound(self.output_encoding)
            self.deferred_check()({"table": self.table}, lambda name, extremes: _check_extremes(extremes, bound), summary=_extremes)

    def check_state(self) -> None:
        """Also the table, the domain and a shaper's curve, as the constructor checks them (a saved LUT is untrusted);
        a learnable table is checked at every forward instead, and nothing on ``meta`` has values to check."""
        super().check_state()
        if in_state_check(self.table):
            _check_table(self.table, self.output_encoding)
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

    def forward(self, image: torch.Tensor, interpolation: Optional[str] = None) -> torch.Tensor:
        interpolation = interpolation or self.interpolation
        _check_arguments(image, self.shaper, interpolation, self.output_encoding)
        arguments = (image, self.rows(working_dtype(image).dtype), self.size, self.shaper, self.domain_min, self.domain_max,
                     interpolation, self.output_range, self.curve, self.curve_range, self.output_encoding)
        if self.compile:
            try:
                return compiled_lookup()(*arguments)
            except Exception as error:  # no C++ compiler, unsupported device, ...: the eager path always works
                warnings.warn(f"LUT3D(compile=True) fell back to eager: torch.compile failed with {error!r}", RuntimeWarning)
                self.compile = False
        return chunked_lookup(*arguments, tables=self._eager_tables(image, arguments[1], interpolation))

    def rows(self, dtype: torch.dtype) -> torch.Tensor:
        """The table as planar rows ``(3, S³)`` in ``dtype`` (:func:`~torchgrade.lut.planar_table`), what the kernels read.

        Cached until the table is replaced, moved or modified in place; computed on every call while
        gradients flow to the table, so autograd sees the conversion.
        """
        table = self.table
        if table.requires_grad and torch.is_grad_enabled():
            return planar_table(table.to(dtype))
        key = (table.data_ptr(), table._version, dtype)
        cached_table, cached_key, rows = self._rows_cache
        if cached_table is not table or cached_key != key:
            rows = planar_table(table.detach().to(dtype))
            self._rows_cache = (table, key, rows)  # holding the table keeps its address from being reused
        return rows

    def _apply(self, fn, *args, **kwargs):
        """Moves and casts drop the eager form's cached tables: they are derived from the table where it was."""
        self._tables_cache = (None, None, None)
        return super()._apply(fn, *args, **kwargs)

    def _eager_tables(self, image: torch.Tensor, rows: torch.Tensor, interpolation: str):
        """The eager form's tables of ``rows`` (:meth:`rows`), cached with them; ``None`` where the lookup of ``image`` will not use them."""
        eager = KERNELS[interpolation].eager
        if eager is None or self.size > eager.max_size or not _in_runs(image, rows):
            return None
        cached_rows, cached_interpolation, tables = self._tables_cache
        if cached_rows is not rows or cached_interpolation != interpolation:
            with torch.no_grad():
                tables = eager.tables(rows, self.size)
            self._tables_cache = (rows, interpolation, tables)
        return tables

    def linear_table(self) -> torch.Tensor:
        """The table with linear output values (decoded by ``output_encoding``), as a ``.cube`` file holds it."""
        return decode_output(self.table, self.output_encoding)

    def export_form(self, interpolation: Optional[str] = None, backend: str = "strip") -> nn.Module:
        """The module an ONNX export traces for this LUT looked up with ``interpolation`` (its own by default), in
        ``backend``'s graph form."""
        interpolation = interpolation or self.interpolation
        check_choice("interpolation", interpolation, KERNELS)
        check_choice("lut_backend", backend, BACKENDS)
        return LUTLookup(self, interpolation, backend)

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
        >>> lookup = LUT3D(identity_table(3)).export_form("trilinear", "strip")
        >>> lookup(torch.full((1, 3, 1, 1), 0.5)).flatten().tolist()
        [0.5, 0.5, 0.5]
    """

    per_pixel = True

    def __init__(self, lut: LUT3D, interpolation: str, backend: str):
        super().__init__()
        self.lut = lut
        self.interpolation = interpolation
        self.grid = KERNELS[interpolation].graph_form(backend)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        if self.grid is None:
            return self.lut(image, self.interpolation)
        lut = self.lut
        x = sanitize(image)
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
    if curve.dim() != 2 or curve.shape[1] != 3 or curve.shape[0] < 2:
        raise ValueError(f"shaper curve must have shape (n >= 2, 3), got {tuple(curve.shape)}")
    return curve


def _short(t: torch.Tensor):
    values = [round(v, 6) for v in t.tolist()]
    return values[0] if len(set(values)) == 1 else tuple(values)
