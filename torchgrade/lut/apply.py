"""The lookup behind :class:`~torchgrade.LUT3D` (:mod:`.layer`): a pixel through the shaper, the lattice and the table, its eager runs and its compile cache.

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
converts once and caches. On the CPU, without autograd, both interpolations run a loop compiled from C on first use
(:mod:`torchgrade.lut.native`): sanitize, domain, cell and interpolation in one vectorised pass per pixel on a
packed table, over whole frames in chunks of :data:`~torchgrade.runtime.LOOKUP_CHUNK` pixels spread over torch's
own OpenMP threads where the frame goes in and out as it is, else on runs on worker threads between the shaper's and
the decoding's operations (``benchmarks/bench_lut_cpu.py`` times it against OpenColorIO). Where it does not compile,
the eager form runs (:func:`chunked_lookup`): one pass per operation over runs of
:data:`~torchgrade.runtime.LOOKUP_CHUNK` pixels, each run on one thread, from 2 intra-op threads up on as many worker
threads taking shares as they come free; tetrahedral there goes through
:class:`~torchgrade.lut.kernels.TetrahedralRuns`, 15 in-place operations a run from value-and-step tables derived
once per LUT. Off the CPU a frame is one pass, :func:`~torchgrade.lut.kernels.tetrahedral_frame`'s 13 operations
where the gather form makes 71 (each a kernel launch on a GPU; ``benchmarks/gpu_proxy.py`` counts them).
``LUT3D(..., compile=True)`` runs non-finite policy, shaper, index math, gathers, weights, decoding and clamp as
one ``torch.compile``d pass with no temporary buffers (for GPUs; on a CPU the compiled loop is faster).

Examples:
    >>> import torch
    >>> from torchgrade.lut import LUT3D, identity_table
    >>> lut = LUT3D(identity_table(5))
    >>> lut(torch.full((1, 3, 2, 2), 0.3)).flatten()[:3].tolist()  # doctest: +ELLIPSIS
    [0.3..., 0.3..., 0.3...]
"""

from __future__ import annotations

import functools
from typing import Callable, Optional

import torch

from ..base.images import HALF_MAX, check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import check_choice
from ..runtime.workers import one_thread
from ..color import linear_to_srgb, srgb_to_linear
from ..runtime import LOOKUP_CHUNK, policy_for, run_pieces, untracked
from .kernels import KERNELS
from .lattice import planar_table
from .native import MAX_SIZE as COMPILED_MAX_SIZE
from .shapers import SHAPERS, lattice_unit, shaper_encode

__all__ = [ "OUTPUT_ENCODINGS", "LOOKUP_CHUNK", "SHARES_PER_WORKER", "EagerTables", "apply_lut", "lookup", "chunked_lookup",
           "compiled_lookup", "decode_output", "encode_output", "table_output"]

OUTPUT_ENCODINGS = ("linear", "srgb")
"""How table entries are stored: linear values, or sRGB-encoded values decoded after the lookup."""

SHARES_PER_WORKER = 4
"""A CPU frame is cut into this many shares per worker thread, taken in turn by whichever worker is free: a worker
whose core another process holds takes fewer of them, instead of holding the frame up with a fixed half."""


class EagerTables:
    """What the eager forms of one planar table ``rows`` ``(3, S³)`` read, each derived on first use and kept:
    :attr:`steps` (:attr:`EagerForm.tables <torchgrade.lut.kernels.EagerForm>`) and :attr:`packed` (``(S³, 3)``, the
    compiled loop's, :mod:`torchgrade.lut.native`).

    Examples:
        >>> import torch
        >>> tables = EagerTables(torch.arange(6.0).view(3, 2), 1, "tetrahedral")
        >>> tables.packed.tolist()
        [[0.0, 2.0, 4.0], [1.0, 3.0, 5.0]]
    """

    def __init__(self, rows: torch.Tensor, size: int, interpolation: str):
        self.rows, self.size, self.form = rows, size, KERNELS[interpolation].eager

    @functools.cached_property
    def steps(self) -> torch.Tensor:
        with torch.no_grad():
            return self.form.tables(self.rows, self.size)

    @functools.cached_property
    def packed(self) -> torch.Tensor:
        return self.rows.detach().t().contiguous()


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
    rows = planar_table(table.to(working_dtype(image).dtype))
    return chunked_lookup(image, rows, table.shape[0], shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding)


def lookup(image, rows, size: int, shaper, domain_min, domain_max, interpolation, output_range, curve, curve_range, output_encoding,
           tables: Optional[torch.Tensor] = None, nan_free: bool = False) -> torch.Tensor:
    """:func:`apply_lut` on a planar table ``rows`` ``(3, size³)`` already in the image's working dtype.

    One pass per pixel from input to output: non-finite policy, shaper, lattice coordinates,
    interpolation, output decoding and clamp. Arguments are not checked (see :func:`apply_lut`);
    this is the function ``LUT3D(..., compile=True)`` compiles. With the eager form's ``tables``
    (:class:`EagerTables`, without autograd) the interpolation is its whole-frame form. ``nan_free``: ``image`` holds no
    NaN (:func:`~torchgrade.base.images.sanitize`).

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
    values = kernel(coords, rows, size) if tables is None else kernel.eager.frame(coords, tables.steps, size)
    y = table_output(values, output_encoding, output_range)
    return to_input_dtype(y.reshape(x.shape).movedim(0, -3), image)


def chunked_lookup(image, rows, size: int, *settings, pixels: Optional[int] = None, tables=None, nan_free: bool = False) -> torch.Tensor:
    """:func:`lookup` (same arguments after ``size``) over ``pixels``-sized runs of each CPU image's pixels, each on one thread.

    Every step is per pixel, so the runs give the one-pass result. On the CPU the runs go through the
    interpolation's compiled loop where it has one and it compiled here (:mod:`torchgrade.lut.native`: tetrahedral up
    to 812³), else through its eager form (:class:`~torchgrade.lut.EagerForm`: tetrahedral up to 65³), else through
    its gather form; the first two read ``tables`` (:class:`EagerTables`, made here when not given; :class:`LUT3D`
    caches them) and give the gather form's values to float rounding. The compiled loop
    takes whole frames where nothing comes before or after it (a linear shaper and output) and spreads chunks of
    ``pixels`` over torch's intra-op threads; otherwise, as the other forms, it runs on runs of ``pixels`` (a shaper's
    passes stay in cache), which go to worker threads in :data:`SHARES_PER_WORKER` shares per worker, taken by
    whichever worker is free. Off the CPU the whole image is one
    pass of :func:`lookup`, through the eager form's whole-frame form where there is one; while gradients
    flow to the image or the table (autograd keeps every temporary anyway) and while tracing (an export
    records one pass), one pass of its gather form. ``nan_free`` is passed to a whole image's :func:`lookup` (runs
    sanitize their own copies).

    Examples:
        >>> import torch
        >>> from torchgrade.lut import identity_table
        >>> from torchgrade.lut.lattice import planar_table
        >>> x = torch.rand(2, 3, 4, 5)
        >>> args = (planar_table(torch.rand(3, 3, 3, 3)), 3, "linear", 0.0, 1.0, "trilinear", None, None, (0.0, 1.0), "linear")
        >>> torch.equal(chunked_lookup(x, *args, pixels=7), lookup(x, *args))
        True
    """
    if not untracked(image, rows):  # the eager forms record no gradient
        return lookup(image, rows, size, *settings, nan_free=nan_free)
    kernel = KERNELS[settings[3]]
    eager = kernel.eager if kernel.eager is not None and size <= kernel.eager.max_size else None
    policy = policy_for(image.device)
    compiled = kernel.compiled(rows.dtype) if kernel.compiled and policy.lookup_chunk and size <= COMPILED_MAX_SIZE else None
    if tables is None and (eager or compiled):
        tables = EagerTables(rows, size, settings[3])
    if policy.lookup_chunk is None:
        return lookup(image, rows, size, *settings, tables=tables if eager else None, nan_free=nan_free)
    pixels = pixels or policy.lookup_chunk
    height, width = image.shape[-2:]
    planes = image.reshape(-1, 3, height * width)
    if compiled and _straight_through(planes, rows.dtype, settings):
        return _compiled_frames(planes, tables.packed, size, settings, compiled, pixels).reshape(image.shape)
    result = torch.empty(planes.shape, dtype=image.dtype)
    if compiled:
        packed = tables.packed  # derived here, once, not in every worker

        def runs(part, out):
            _compiled_runs(part, out, packed, size, settings, pixels, compiled)
    elif eager:
        steps = tables.steps

        def runs(part, out):
            _eager_lookup(part, out, rows, size, settings, pixels, eager, steps)
    else:
        def runs(part, out):
            _gather_runs(part, out, rows, size, settings, pixels)

    def share(span: tuple) -> None:
        begin, end = span
        runs(planes[..., begin:end], result[..., begin:end])

    shares = _shares(height * width, pixels, policy.workers * SHARES_PER_WORKER if policy.workers > 1 else 1)
    if policy.workers > 1:
        run_pieces(share, shares, policy.workers)
    else:
        with one_thread():
            share(shares[0])
    return result.reshape(image.shape)


def _shares(count: int, pixels: int, shares: int) -> list:
    """``[(begin, end), ...]``: ``count`` pixels cut into at most ``shares`` contiguous shares of whole runs.

    Examples:
        >>> _shares(10, 3, 2), _shares(10, 3, 1)
        ([(0, 6), (6, 10)], [(0, 10)])
    """
    runs = -(-count // pixels)
    per_share = -(-runs // max(1, shares)) * pixels
    return [(begin, min(begin + per_share, count)) for begin in range(0, count, per_share)]


def _gather_runs(planes, result, rows, size, settings, pixels) -> None:
    """:func:`chunked_lookup` through the gather form: ``planes`` ``(N, 3, P)`` into ``result``, runs of ``pixels``."""
    for frame, out in zip(planes, result):
        for start in range(0, frame.shape[-1], pixels):
            run = frame[:, start:start + pixels].unsqueeze(-1)  # (3, run, 1): an image of one column
            out[:, start:start + run.shape[1]] = lookup(run, rows, size, *settings).squeeze(-1)


def _straight_through(planes: torch.Tensor, dtype: torch.dtype, settings: tuple) -> bool:
    """Whether the compiled loop takes ``planes`` ``(N, 3, P)`` as they are and its values are the result
    (:func:`_read_as_they_are`, :func:`_values_are_the_output`)."""
    shaper, _, _, _, output_range, _, _, output_encoding = settings
    return _read_as_they_are(planes, dtype, shaper) and _values_are_the_output(planes.dtype, dtype, output_encoding, output_range)


def _read_as_they_are(planes: torch.Tensor, dtype: torch.dtype, shaper: str) -> bool:
    """Whether the compiled loop reads ``planes`` without a buffer: a linear shaper (the loop sanitizes and maps the
    domain itself) on rows of the table's ``dtype``."""
    return shaper == "linear" and planes.dtype == dtype and planes.stride(-1) == 1


def _values_are_the_output(result_dtype: torch.dtype, dtype: torch.dtype, output_encoding: str, output_range) -> bool:
    """Whether interpolated values of ``dtype`` are the lookup's output as they are: linear entries, no clamp, the
    result's dtype."""
    return output_encoding == "linear" and output_range is None and result_dtype == dtype


def _compiled_frames(planes, packed, size, settings, interpolate, pixels) -> torch.Tensor:
    """:func:`chunked_lookup` through a compiled loop (:mod:`torchgrade.lut.native`) where it takes the frames as they
    are (:func:`_straight_through`): whole frames, chunks of ``pixels`` over torch's intra-op threads, no temporary."""
    low, scale = _domain_columns(settings[1], settings[2], size, packed.dtype)
    return interpolate(planes, torch.empty(planes.shape, dtype=planes.dtype), low, scale, packed, size, pixels)


def _compiled_runs(planes, result, packed, size, settings, pixels, interpolate) -> None:
    """:func:`chunked_lookup` through a compiled loop, one thread, runs of ``pixels`` (cache-sized: a shaper's and a
    decoding's passes stay in cache): ``planes`` ``(N, 3, P)`` into ``result``. The loop sanitizes and maps the domain
    itself; another shaper, dtype or layout goes through a buffer first, a decoding or clamp of the output after."""
    shaper, domain_min, domain_max, _, output_range, curve, curve_range, output_encoding = settings
    dtype = packed.dtype
    run = max(1, min(pixels, planes.shape[-1]))
    as_is = _read_as_they_are(planes, dtype, shaper)
    codes = None if as_is else torch.empty(3, run, dtype=dtype)
    direct = _values_are_the_output(result.dtype, dtype, output_encoding, output_range)
    values = None if direct else torch.empty(3, run, dtype=dtype)
    low, scale = _domain_columns(domain_min, domain_max, size, dtype)
    for frame, out in zip(planes, result):
        for start in range(0, frame.shape[-1], run):
            x = frame[:, start:start + run]
            n = x.shape[-1]
            if not as_is:
                buffer = codes[:, :n]
                x = buffer.copy_(x) if shaper == "linear" else _sanitized_codes(x, buffer, shaper, curve, curve_range).contiguous()
            y = out[:, start:start + n] if direct else values[:, :n]
            interpolate(x.unsqueeze(0), y.unsqueeze(0), low, scale, packed, size, run)
            if not direct:
                out[:, start:start + n] = to_input_dtype(table_output(y, output_encoding, output_range), out)


def _sanitized_codes(x: torch.Tensor, buffer: torch.Tensor, shaper: str, curve, curve_range) -> torch.Tensor:
    """``shaper_encode(sanitize(x))`` of pixels ``(3, n)``, sanitized into ``buffer`` (in its dtype): the non-finite
    policy's clamp and NaN pass in place, then the shaper (in ``buffer`` where it works in place, else a new tensor).

    Examples:
        >>> import torch
        >>> x = torch.tensor([[float("nan")], [float("inf")], [0.5]])
        >>> _sanitized_codes(x, torch.empty(3, 1), "linear", None, (0.0, 1.0)).flatten().tolist()
        [0.0, 65504.0, 0.5]
    """
    if x.dtype != buffer.dtype:
        x = buffer.copy_(x)
    torch.clamp(x, -HALF_MAX, HALF_MAX, out=buffer).nan_to_num_(nan=0.0)
    return shaper_encode(buffer, shaper, curve, curve_range)


def _domain_columns(domain_min, domain_max, size: int, dtype) -> tuple:
    """The domain's low end and ``(size - 1) / span`` ``(3,)`` in ``dtype``: lattice coordinates are ``(code - low) * scale``."""
    low = torch.as_tensor(domain_min, dtype=dtype).reshape(-1).expand(3).contiguous()
    span = torch.as_tensor(domain_max, dtype=dtype).reshape(-1).expand(3) - low
    return low, ((size - 1) / span).contiguous()


def _eager_lookup(planes, result, rows, size, settings, pixels, eager, tables) -> None:
    """:func:`chunked_lookup` through an eager form from its ``tables``: ``planes`` ``(N, 3, P)`` into ``result``, runs
    of ``pixels``."""
    shaper, domain_min, domain_max, _, output_range, curve, curve_range, output_encoding = settings
    run = max(1, min(pixels, planes.shape[-1]))
    runs = eager.runs(tables, size, run)
    direct = _values_are_the_output(result.dtype, rows.dtype, output_encoding, output_range)
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
        if self.unclamped:
            x = buffer.copy_(x) if x.dtype != self.dtype else x
            codes = torch.nan_to_num(x, nan=0.0, posinf=HALF_MAX, neginf=-HALF_MAX, out=buffer)
        else:
            codes = _sanitized_codes(x, buffer, self.shaper, self.curve, self.curve_range)
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
