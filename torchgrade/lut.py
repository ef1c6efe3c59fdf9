"""3D LUTs: bake any per-pixel transform into a lattice, apply it with trilinear or tetrahedral interpolation.

A :class:`LUT3D` maps a linear Rec.709 pixel ``x`` to an output colour in five steps::

    s = shaper(x)                                   # "linear": s = x; "logc": s = LogC(x); "curve": 1D table
    u = clamp((s - domain_min) / (domain_max - domain_min), 0, 1)      # per channel
    y = interpolate(table, u * (size - 1))          # trilinear or tetrahedral, lattice points exact
    y = decode(y, output_encoding)                  # "linear": y; "srgb": sRGB decoding
    y = clamp(y, *output_range)                     # only for display-referred LUTs

**Lattice and table layout.** ``table`` has shape ``(size, size, size, 3)`` indexed ``[b, g, r, channel]``,
so ``table.reshape(-1, 3)`` lists the entries with red fastest, the order of a ``.cube`` file. Lattice
point ``i`` of an axis sits at ``u = i / (size - 1)``: the end points are on the domain bounds, which is
``grid_sample``'s ``align_corners=True`` convention (and that of ``.cube`` files and OpenColorIO).

**Shapers** (Catlike Coding, Color Grading §3.4). ``"linear"`` spends the lattice evenly on
``[0, 1]``; ``"logc"`` uses Unity's ARRI LogC curve (:func:`torchgrade.color.linear_to_logc`) so the
lattice covers scene-referred values up to ``logc_to_linear(1) ≈ 58.9``. The LogC domain starts at
``LogC(0) ≈ 0.064``, not at 0 as in the document: a lattice plane then lies exactly on black, where
every grade and tone mapper has its ``max(0, ·)`` kink, and no lattice points are spent on negative
inputs (which clamp to black, as the tone mappers do anyway). ``"curve"`` is a per-channel 1D table
over a linear input range, as ``.cube`` files carry it (read from files, never baked).

**Output encoding.** A table may store sRGB-encoded outputs (``output_encoding="srgb"``, decoded
after the lookup, sign-preserving): the interpolation error is then spread evenly over display code
values instead of piling up in the shadows. ``bake_lut`` stores linear outputs unless asked.

**Display-referred LUTs** (baked from a transform with a :class:`~torchgrade.ToneMap`) record
``output_range = (0, 1)``: the clip happens *after* the lookup. A transform that ends with
its tone mapper is baked with that tone mapper's clip off (``ToneMap.clip``), so the table holds a
smooth curve and the clip is exact instead of interpolated. Kinks inside the transform (the tone
mapper's ``max(0, ·)`` of its graded input, on surfaces oblique to the lattice) stay in the table and
are what limits a 33³ LUT's accuracy on strong looks.

**Speed.** The lookup is gather-based (integer lattice indices, one 1-D gather per vertex and channel
on a planar ``(3, size³)`` table that :meth:`LUT3D.rows` converts once and caches), with a
``grid_sample`` trilinear form kept for 4-D/5-D GridSample exporters. Every step is per pixel, so
``LUT3D(..., compile=True)`` runs non-finite policy, shaper, index math, gathers, weights, decoding
and clamp as one ``torch.compile``d pass with no temporary buffers; the eager default makes one pass
per operation. benchmarks/bench_lut.py measures both against OpenColorIO.
"""

from __future__ import annotations

import contextlib
import math
import numbers
import warnings
from typing import Callable, Optional, Sequence

import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm

from .color import linear_to_logc, linear_to_srgb, logc_to_linear, srgb_to_linear
from .core import check_image, sanitize, to_input_dtype, working_dtype
from .tonemap import ToneMap

MIN_SIZE, MAX_SIZE = 2, 256
"""Lattice sizes accepted by :func:`bake_lut` and :class:`LUT3D` (points per axis)."""

SHAPERS = ("linear", "logc", "curve")
INTERPOLATIONS = ("trilinear", "tetrahedral")

LOGC_BLACK = float(linear_to_logc(torch.tensor(0.0, dtype=torch.float64)))
"""LogC code value of linear 0 (≈ 0.064 with Unity's constants): the bottom of the LogC lattice."""

DEFAULT_DOMAINS = {"linear": (0.0, 1.0), "logc": (LOGC_BLACK, 1.0)}
"""Lattice domain of each shaper, in shaper code values (LogC 1.0 is linear ≈ 58.86)."""

AUTO_SIZES = (3, 5, 9, 17, 33, 65, 129, 256)
"""Sizes tried first by ``bake_lut(size="auto")`` before bisecting between the last two."""


def check_size(size) -> int:
    """Return ``size`` as an int, or raise ``ValueError`` unless it is an integer in [2, 256]."""
    if isinstance(size, bool) or not isinstance(size, numbers.Integral) or not MIN_SIZE <= size <= MAX_SIZE:
        raise ValueError(f"LUT size must be an integer from {MIN_SIZE} to {MAX_SIZE} (points per axis), got {size!r}")
    return int(size)


def _check_choice(value: str, choices: Sequence[str], what: str) -> None:
    if value not in choices:
        raise ValueError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")


# ---------------------------------------------------------------- shapers


def shaper_encode(points: torch.Tensor, shaper: str, curve: Optional[torch.Tensor] = None, curve_range=(0.0, 1.0)) -> torch.Tensor:
    """Shaper code values of linear ``(3, P)`` points: identity, :func:`linear_to_logc`, or :func:`sample_curve`."""
    if shaper == "linear":
        return points
    if shaper == "logc":
        return linear_to_logc(points)
    return sample_curve(points, curve, curve_range)


def shaper_decode(codes: torch.Tensor, shaper: str) -> torch.Tensor:
    """Linear values of shaper code values: the inverse of :func:`shaper_encode` for "linear" and "logc"."""
    return codes if shaper == "linear" else logc_to_linear(codes)


def sample_curve(points: torch.Tensor, curve: torch.Tensor, curve_range) -> torch.Tensor:
    """Per-channel 1D table lookup on ``(3, P)`` points, linear interpolation, inputs clamped to ``curve_range``.

    ``curve`` is ``(n, 3)``; entry ``k`` is the output at ``lo + k (hi - lo) / (n - 1)`` (a ``.cube`` 1D
    shaper, as Resolve and OpenColorIO read it).
    """
    lo, hi = curve_range
    n = curve.shape[0]
    position = ((points - lo) / (hi - lo)).clamp(0.0, 1.0) * (n - 1)
    index = position.floor().clamp(max=n - 2)
    fraction = position - index
    planar = curve.to(points).t()
    lower = torch.gather(planar, 1, index.long())
    upper = torch.gather(planar, 1, index.long() + 1)
    return lower + fraction * (upper - lower)


# ---------------------------------------------------------------- lattice


def lattice(size: int, dtype=torch.float64, device=None) -> torch.Tensor:
    """Lattice coordinates ``u`` in [0, 1], shape ``(size, size, size, 3)``: ``[b, g, r] -> (r, g, b) / (size - 1)``."""
    size = check_size(size)
    axis = torch.linspace(0.0, 1.0, size, dtype=dtype, device=device)
    b, g, r = torch.meshgrid(axis, axis, axis, indexing="ij")
    return torch.stack((r, g, b), dim=-1)


def identity_table(size: int, dtype=torch.float32) -> torch.Tensor:
    """The table that returns its lattice coordinates ``u``: an identity LUT on the domain [0, 1]."""
    return lattice(size, torch.float64).to(dtype)


# ---------------------------------------------------------------- interpolation


def planar_table(table: torch.Tensor) -> torch.Tensor:
    """``(S, S, S, 3)`` table as ``(3, S³)``: row ``c`` holds channel ``c`` at flat index ``r + S g + S² b``."""
    return table.reshape(-1, 3).t().contiguous()


def _cell(coords: torch.Tensor, size: int):
    """Split lattice coordinates ``(3, P)`` in [0, S-1] into the cell's flat int32 base index and the fractions.

    The index is formed in floating point (exact: at most 255³ < 2²⁴) and converted once.
    """
    corner = coords.floor().clamp(max=size - 2)
    fraction = coords - corner
    base = (corner[0] + size * corner[1] + (size * size) * corner[2]).to(torch.int32)
    return base, fraction.unbind(0)


def tetrahedral(coords: torch.Tensor, table: torch.Tensor, size: int) -> torch.Tensor:
    """Tetrahedral interpolation of a planar table ``(3, S³)`` at lattice coordinates ``(3, P)`` -> ``(3, P)``.

    The cube cell is split along its main diagonal into 6 tetrahedra, picked by the order of the
    fractions ``f_a >= f_b >= f_c`` (Kasson, Nin and Plouffe 1995; the scheme OpenColorIO uses)::

        y = c000 + f_a (v1 - c000) + f_b (v2 - v1) + f_c (c111 - v2)

    where ``v1`` steps from ``c000`` along the largest fraction's axis and ``v2 = c111`` minus a step
    along the smallest one's. Exact on lattice points and continuous across cells; on ties the
    ambiguous vertex gets weight 0. Every step is per pixel and per table row (one 1-D gather per
    vertex and channel), so ``torch.compile`` fuses it into a single pass over the pixels.
    """
    base, (fr, fg, fb) = _cell(coords, size)
    f_max = torch.maximum(torch.maximum(fr, fg), fb)
    f_min = torch.minimum(torch.minimum(fr, fg), fb)
    f_mid = fr + fg + fb - f_max - f_min
    plane = size * size
    stride_max = torch.where(fr >= fg, torch.where(fr >= fb, 1, plane), torch.where(fg >= fb, size, plane))
    stride_min = torch.where(fr < fg, torch.where(fr < fb, 1, plane), torch.where(fg < fb, size, plane))
    diagonal = 1 + size + plane
    v1_index = base + stride_max
    v2_index = base + (diagonal - stride_min)
    c111_index = base + diagonal

    def channel(row: torch.Tensor) -> torch.Tensor:
        c000, v1, v2, c111 = row[base], row[v1_index], row[v2_index], row[c111_index]
        return c000 + f_max * (v1 - c000) + f_mid * (v2 - v1) + f_min * (c111 - v2)

    return torch.stack([channel(row) for row in table.unbind(0)])


def trilinear(coords: torch.Tensor, table: torch.Tensor, size: int) -> torch.Tensor:
    """Trilinear interpolation of a planar table ``(3, S³)`` at lattice coordinates ``(3, P)`` -> ``(3, P)``.

    ``y = lerp_b(lerp_g(lerp_r(c000, c100), lerp_r(c010, c110)), lerp_g(...))`` over the 8 corners,
    per table row as in :func:`tetrahedral`.
    """
    base, (fr, fg, fb) = _cell(coords, size)

    def channel(row: torch.Tensor) -> torch.Tensor:
        def lerp_r(index):
            low = row[index]
            return low + fr * (row[index + 1] - low)

        def lerp_g(index):
            low = lerp_r(index)
            return low + fg * (lerp_r(index + size) - low)

        low = lerp_g(base)
        return low + fb * (lerp_g(base + size * size) - low)

    return torch.stack([channel(row) for row in table.unbind(0)])


def trilinear_grid_sample(unit: torch.Tensor, table: torch.Tensor) -> torch.Tensor:
    """Trilinear lookup with 5-D ``grid_sample``: ``unit`` ``(N, 3, H, W)`` in [0, 1] -> ``(N, 3, H, W)``.

    The volume is ``(1, 3, D=b, H=g, W=r)`` and the grid holds ``(x, y, z) = (r, g, b)`` mapped to
    [-1, 1]. With ``align_corners=True`` -1 and +1 are the *centres* of the first and last lattice
    points, so ``u = i / (S - 1)`` lands exactly on lattice point ``i`` (with ``align_corners=False``
    they would be the outer edges of the texels and every lookup would be off by half a cell).
    """
    volume = table.permute(3, 0, 1, 2).unsqueeze(0).expand(unit.shape[0], -1, -1, -1, -1)
    grid = (unit * 2.0 - 1.0).permute(0, 2, 3, 1).unsqueeze(1)
    return F.grid_sample(volume, grid, mode="bilinear", padding_mode="border", align_corners=True).squeeze(2)


_KERNELS = {"trilinear": trilinear, "tetrahedral": tetrahedral}

OUTPUT_ENCODINGS = ("linear", "srgb")
"""How table entries are stored: linear values, or sRGB-encoded values decoded after the lookup."""


def decode_output(values: torch.Tensor, encoding: str) -> torch.Tensor:
    """Linear output of interpolated table values: identity, or :func:`torchgrade.color.srgb_to_linear`.

    sRGB decoding is sign-preserving (linear segment below 0) and defined above 1, so any table encodes.
    """
    return values if encoding == "linear" else srgb_to_linear(values)


def encode_output(values: torch.Tensor, encoding: str) -> torch.Tensor:
    """Table entries of linear outputs: the inverse of :func:`decode_output`."""
    return values if encoding == "linear" else linear_to_srgb(values)


def apply_lut(
    image: torch.Tensor,
    table: torch.Tensor,
    shaper: str = "linear",
    domain_min=0.0,
    domain_max=1.0,
    interpolation: str = "tetrahedral",
    output_range=None,
    curve: Optional[torch.Tensor] = None,
    curve_range=(0.0, 1.0),
    output_encoding: str = "linear",
) -> torch.Tensor:
    """Apply a 3D LUT to a linear image ``(..., 3, H, W)``; see the module docstring for the steps.

    Non-finite pixels follow the library policy (:func:`torchgrade.core.sanitize`) before the
    shaper; inputs outside the domain clamp to it. Differentiable with respect to the image and the
    table; float16/bfloat16 are computed in float32.
    """
    _check_arguments(image, shaper, interpolation, output_encoding)
    rows = planar_table(table.to(working_dtype(image).dtype))
    return lookup(image, rows, table.shape[0], shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding)


def _check_arguments(image: torch.Tensor, shaper: str, interpolation: str, output_encoding: str) -> None:
    check_image(image)
    _check_choice(interpolation, INTERPOLATIONS, "interpolation")
    _check_choice(shaper, SHAPERS, "shaper")
    _check_choice(output_encoding, OUTPUT_ENCODINGS, "output encoding")


def lookup(image, rows, size: int, shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding) -> torch.Tensor:
    """:func:`apply_lut` on a planar table ``rows`` ``(3, size³)`` already in the image's working dtype.

    One pass per pixel from input to output: non-finite policy, shaper, lattice coordinates,
    interpolation, output decoding and clamp. Arguments are not checked (see :func:`apply_lut`);
    this is the function ``LUT3D(..., compile=True)`` compiles.
    """
    x = sanitize(working_dtype(image)).movedim(-3, 0)  # (3, ..., H, W): a view
    unit = lattice_unit(x.reshape(3, -1), shaper, domain_min, domain_max, curve, curve_range)
    y = table_output(_KERNELS[interpolation](unit * (size - 1), rows, size), output_encoding, output_range)
    return to_input_dtype(y.reshape(x.shape).movedim(0, -3), image)


def table_output(values: torch.Tensor, output_encoding: str, output_range) -> torch.Tensor:
    """A LUT's output from interpolated table values: :func:`decode_output`, then the clamp to ``output_range`` (if any)."""
    y = decode_output(values, output_encoding)
    return y if output_range is None else y.clamp(*output_range)


def lattice_unit(points, shaper, domain_min, domain_max, curve=None, curve_range=(0.0, 1.0)) -> torch.Tensor:
    """Normalised lattice coordinates ``u = clamp((shaper(x) - min) / (max - min), 0, 1)`` of ``(3, P)`` points."""
    low = _channel_column(domain_min, points)
    high = _channel_column(domain_max, points)
    codes = shaper_encode(points, shaper, curve, curve_range)
    return ((codes - low) / (high - low)).clamp(0.0, 1.0)


def _channel_column(value, like: torch.Tensor) -> torch.Tensor:
    """A number or RGB triple as a ``(3, 1)`` column in ``like``'s dtype and device."""
    return torch.as_tensor(value, dtype=like.dtype, device=like.device).reshape(-1, 1).expand(3, 1)


# ---------------------------------------------------------------- the module


class LUT3D(nn.Module):
    """A baked 3D LUT: ``LUT3D(table, shaper="linear")(image, interpolation="tetrahedral")``.

    Args:
        table: ``(S, S, S, 3)`` indexed ``[b, g, r, channel]`` (red fastest), ``2 <= S <= 256``.
        shaper: ``"linear"``, ``"logc"`` or ``"curve"`` (then ``curve`` ``(n, 3)`` and ``curve_range``).
        domain: ``(min, max)`` of the lattice in shaper code values, numbers or RGB triples;
            default :data:`DEFAULT_DOMAINS` for the shaper (``(0, 1)`` for curves).
        output_range: ``(low, high)`` clamp applied after the lookup, or ``None``.
        output_encoding: ``"linear"`` (entries are linear outputs) or ``"srgb"`` (entries are
            sRGB-encoded and decoded after the lookup; :func:`linear_table` gives linear entries).
        learnable: hold the table as an ``nn.Parameter`` (fit a LUT by gradient descent).
        compile: run the lookup through ``torch.compile``: one fused pass over the pixels, several
            times faster than eager, but the first call per interpolation and dtype compiles
            (seconds; see benchmarks/results/lut.md).
    """

    def __init__(
        self,
        table: torch.Tensor,
        shaper: str = "linear",
        domain=None,
        output_range=None,
        curve: Optional[torch.Tensor] = None,
        curve_range=(0.0, 1.0),
        learnable: bool = False,
        compile: bool = False,
        output_encoding: str = "linear",
    ):
        super().__init__()
        _check_choice(shaper, SHAPERS, "shaper")
        _check_choice(output_encoding, OUTPUT_ENCODINGS, "output encoding")
        _check_table(table)
        if (shaper == "curve") != (curve is not None):
            raise ValueError("a 'curve' shaper needs curve=(n, 3) table, and only it takes one")
        self.shaper = shaper
        self.size = table.shape[0]
        if learnable:
            self.table = nn.Parameter(table.detach().clone())
        else:
            self.register_buffer("table", table)
        low, high = checked_domain(domain if domain is not None else DEFAULT_DOMAINS.get(shaper, (0.0, 1.0)))
        self.register_buffer("domain_min", low)
        self.register_buffer("domain_max", high)
        self.register_buffer("curve", None if curve is None else _check_curve(curve))
        self.curve_range = tuple(float(v) for v in curve_range)
        self.output_range = None if output_range is None else tuple(float(v) for v in output_range)
        self.output_encoding = output_encoding
        self.compile = bool(compile)
        self._rows_cache = (None, None, None)

    def forward(self, image: torch.Tensor, interpolation: str = "tetrahedral") -> torch.Tensor:
        _check_arguments(image, self.shaper, interpolation, self.output_encoding)
        arguments = (
            image,
            self.rows(working_dtype(image).dtype),
            self.size,
            self.shaper,
            self.domain_min,
            self.domain_max,
            interpolation,
            self.output_range,
            self.curve,
            self.curve_range,
            self.output_encoding,
        )
        if self.compile:
            try:
                return compiled_lookup()(*arguments)
            except Exception as error:  # no C++ compiler, unsupported device, ...: the eager path always works
                warnings.warn(f"LUT3D(compile=True) fell back to eager: torch.compile failed with {error!r}", RuntimeWarning)
                self.compile = False
        return lookup(*arguments)

    def rows(self, dtype: torch.dtype) -> torch.Tensor:
        """The table as planar rows ``(3, S³)`` in ``dtype`` (:func:`planar_table`), what the kernels read.

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

    def linear_table(self) -> torch.Tensor:
        """The table with linear output values (decoded by :attr:`output_encoding`), as a ``.cube`` file holds it."""
        return decode_output(self.table, self.output_encoding)

    def extra_repr(self) -> str:
        domain = f"domain=({_short(self.domain_min)}, {_short(self.domain_max)})"
        clamp = f", output_range={self.output_range}" if self.output_range else ""
        encoding = f", output_encoding={self.output_encoding!r}" if self.output_encoding != "linear" else ""
        return f"size={self.size}, shaper={self.shaper!r}, {domain}{clamp}{encoding}"


def _check_table(table) -> None:
    if not isinstance(table, torch.Tensor) or not table.is_floating_point():
        raise TypeError(f"LUT table must be a floating-point tensor, got {getattr(table, 'dtype', type(table).__name__)}")
    size = table.shape[0] if table.dim() == 4 else None
    if table.dim() != 4 or table.shape != (size, size, size, 3):
        raise ValueError(f"LUT table must have shape (S, S, S, 3), got {tuple(table.shape)}")
    check_size(size)


def _check_curve(curve: torch.Tensor) -> torch.Tensor:
    if curve.dim() != 2 or curve.shape[1] != 3 or curve.shape[0] < 2:
        raise ValueError(f"shaper curve must have shape (n >= 2, 3), got {tuple(curve.shape)}")
    return curve


def checked_domain(domain) -> tuple:
    """A lattice domain ``(min, max)`` as two float32 RGB triples, or ``ValueError`` unless finite with max > min per channel."""
    try:
        low, high = domain
    except (TypeError, ValueError):
        raise ValueError(f"LUT domain must be a (min, max) pair, got {domain!r}") from None
    low, high = _rgb(low, "domain min"), _rgb(high, "domain max")
    if bool((high <= low).any()):
        raise ValueError(f"LUT domain max must exceed min, got {low.tolist()} and {high.tolist()}")
    return low, high


def _rgb(value, name: str) -> torch.Tensor:
    try:
        t = torch.as_tensor(value, dtype=torch.float32).detach().reshape(-1)
    except (TypeError, ValueError, RuntimeError):
        raise ValueError(f"LUT {name} must be a finite number or RGB triple, got {value!r}") from None
    if t.numel() == 1:
        t = t.expand(3)
    if t.numel() != 3 or not bool(torch.isfinite(t).all()):
        raise ValueError(f"LUT {name} must be a finite number or RGB triple, got {value!r}")
    return t.clone()


def _short(t: torch.Tensor):
    values = [round(v, 6) for v in t.tolist()]
    return values[0] if len(set(values)) == 1 else tuple(values)


_COMPILED = None


def compiled_lookup() -> Callable:
    """:func:`lookup` through ``torch.compile`` (created once, on first use; pixel counts become dynamic
    after the first recompile, so new frame sizes do not compile again)."""
    global _COMPILED
    if _COMPILED is None:
        _COMPILED = torch.compile(lookup)
    return _COMPILED


# ---------------------------------------------------------------- baking


def expects_hdr(transform) -> bool:
    """The rule behind ``shaper="auto"``: does ``transform`` take scene-referred (HDR) input?

    An explicit ``transform.expects_hdr`` attribute wins; otherwise a transform that is or contains
    a :class:`~torchgrade.ToneMap` with a curve (any mode but ``"none"``) is HDR. Everything else
    (a grade alone, a plain function) is treated as taking [0, 1] input.
    """
    declared = getattr(transform, "expects_hdr", None)
    if declared is not None:
        return bool(declared)
    return any(t.mode != "none" for t in _tone_mappers(transform))


def _tone_mappers(transform) -> list:
    modules = transform.modules() if isinstance(transform, nn.Module) else ()
    return [m for m in modules if isinstance(m, ToneMap)]


def bake_lut(
    transform: Callable[[torch.Tensor], torch.Tensor],
    size=33,
    shaper: str = "auto",
    scene: Optional[torch.Tensor] = None,
    tolerance: float = 0.5,
    chunk: int = 1 << 21,
    output_encoding: str = "linear",
    progress: bool = False,
    domain: Optional[tuple] = None,
) -> LUT3D:
    """Bake a per-pixel ``transform`` on ``(N, 3, H, W)`` tensors into a :class:`LUT3D`.

    The transform is evaluated once on the lattice, in float64 and in shaper space, and the float64 table kept (lattice point
    ``u`` is fed ``shaper_decode(min + u (max - min))``), ``chunk`` points at a time. The table stays
    connected to the transform's parameters, so a LUT can be fitted by gradient descent.

    * ``shaper``: ``"linear"``, ``"logc"`` or ``"auto"`` (``"logc"`` when :func:`expects_hdr`);
      the choice is stored as ``lut.shaper`` and shown in ``repr(lut)``.
    * ``scene``: an image the LUT is for. The lattice domain then follows its dynamic range: the
      top is the scene's largest value (after the non-finite policy), the bottom stays at black.
    * ``domain``: ``(min, max)`` of the lattice in shaper code values (numbers or RGB triples, as
      :class:`LUT3D` takes them), overriding the shaper's default and the scene's range (a ``scene``
      then only serves ``size="auto"``).
    * ``size``: 2..256, or ``"auto"`` with a ``scene``: the smallest size whose error on the scene is
      at most ``tolerance`` 8-bit sRGB code values at the 99.9th percentile (:func:`srgb_code_error`,
      against direct float64 evaluation). Sizes :data:`AUTO_SIZES` are tried in order, then the gap
      below the first that passes is bisected (error is assumed to fall as the size grows); if none
      passes, 256 is returned.
    * ``output_encoding``: how the table stores outputs (:data:`OUTPUT_ENCODINGS`). ``"srgb"`` spreads
      the interpolation error evenly over display code values, which suits display-referred LUTs
      (benchmarks/results/lut.md lists the gain on real images).
    * A transform containing a :class:`~torchgrade.ToneMap` is display-referred: the LUT clamps to
      [0, 1] after the lookup. When the transform *ends* with the tone mapper, it is evaluated
      without its final clip (:func:`_final_clip_off`), so the clip is applied exactly after the
      lookup instead of being interpolated.
    * ``progress``: show a progress bar (tqdm, on stderr, when it is a terminal) while the lattice
      is evaluated; a 256³ bake of a grade and tone mapper takes seconds.
    """
    if shaper == "auto":
        shaper = "logc" if expects_hdr(transform) else "linear"
    _check_choice(shaper, ("linear", "logc"), "bake shaper")
    if domain is None:
        domain = DEFAULT_DOMAINS[shaper] if scene is None else scene_domain(scene, shaper)
    domain = checked_domain(domain)  # the lattice is baked where the lookup will find it
    _check_choice(output_encoding, OUTPUT_ENCODINGS, "output encoding")
    display = bool(_tone_mappers(transform))
    output_range = (0.0, 1.0) if display else None

    def bake(n: int) -> LUT3D:
        with _final_clip_off(transform) if display else contextlib.nullcontext():
            table = encode_output(_evaluate_on_lattice(transform, n, shaper, domain, chunk, progress), output_encoding)
        return LUT3D(table, shaper=shaper, domain=domain, output_range=output_range, output_encoding=output_encoding)

    if size != "auto":
        return bake(check_size(size))
    if scene is None:
        raise ValueError('bake_lut(size="auto") needs scene=image to measure the error on')
    if not tolerance > 0:
        raise ValueError(f'bake_lut(size="auto") needs a tolerance above 0 (8-bit codes), got {tolerance}')
    return _smallest_within(bake, transform, scene, tolerance)


@contextlib.contextmanager
def _final_clip_off(transform):
    """Within the block, the :class:`~torchgrade.ToneMap` that produces ``transform``'s output runs with ``clip=False``.

    That tone mapper is ``transform`` itself or the last module of nested ``nn.Sequential`` containers;
    any other transform is left as it is. Only valid when the LUT clamps to [0, 1] after the lookup.
    """
    final = transform
    while isinstance(final, nn.Sequential) and len(final):
        final = final[-1]
    if not isinstance(final, ToneMap) or not final.clip:
        yield
        return
    final.clip = False
    try:
        yield
    finally:
        final.clip = True


def scene_domain(scene: torch.Tensor, shaper: str) -> tuple:
    """Lattice domain ``(black, shaper(max(scene)))`` in shaper code values, for :func:`bake_lut`."""
    check_image(scene, "scene")
    top = sanitize(scene.detach().double()).max().clamp_min(1e-3)
    return DEFAULT_DOMAINS[shaper][0], float(shaper_encode(top, shaper))


def _evaluate_on_lattice(transform, size: int, shaper: str, domain, chunk: int, progress: bool = False) -> torch.Tensor:
    """Evaluate ``transform`` at every lattice point, float64; returns the ``(S, S, S, 3)`` table.

    ``progress`` shows a bar over the blue slices of the lattice (on a terminal only).
    """
    low, high = (torch.as_tensor(v, dtype=torch.float64) for v in domain)
    inputs = shaper_decode(low + lattice(size) * (high - low), shaper)  # (b, g, r, 3)
    slices_per_chunk = max(1, chunk // (size * size))
    outputs = []
    with tqdm(total=size, desc=f"baking {size}³", unit="slice", disable=None if progress else True, leave=False) as bar:
        for block in inputs.split(slices_per_chunk, dim=0):
            image = block.reshape(1, -1, size, 3).permute(0, 3, 1, 2)  # H = b·S + g, W = r
            result = transform(image)
            check_image(result, "transform output")
            outputs.append(result.double().permute(0, 2, 3, 1).reshape(-1, size, size, 3))
            bar.update(block.shape[0])
    return torch.cat(outputs, dim=0)


def srgb_code_error(reference: torch.Tensor, approximation: torch.Tensor, quantile: float = 0.999) -> float:
    """Absolute error in 8-bit sRGB code values, ``255 |srgb(clamp(a, 0, 1)) - srgb(clamp(b, 0, 1))|``, at ``quantile``."""
    codes = [255.0 * linear_to_srgb(t.detach().double().clamp(0.0, 1.0)) for t in (reference, approximation)]
    error = (codes[0] - codes[1]).abs().flatten()
    rank = max(1, math.ceil(quantile * error.numel()))
    return float(error.kthvalue(rank).values)


def _smallest_within(bake: Callable[[int], LUT3D], transform, scene: torch.Tensor, tolerance: float) -> LUT3D:
    """The LUT of the smallest size whose :func:`srgb_code_error` on ``scene`` is within ``tolerance``."""
    with torch.no_grad():
        reference = transform(sanitize(scene.double()))

    def passes(lut: LUT3D) -> bool:
        with torch.no_grad():
            return srgb_code_error(reference, lut(scene.double())) <= tolerance

    smaller = MIN_SIZE - 1
    for candidate in AUTO_SIZES:
        lut = bake(candidate)
        if passes(lut):
            break
        smaller = candidate
    else:
        return lut
    while candidate - smaller > 1:
        middle = (candidate + smaller) // 2
        trial = bake(middle)
        if passes(trial):
            candidate, lut = middle, trial
        else:
            smaller = middle
    return lut
