"""LUT interpolation kernels: a registry of interpolations, each with its gather form and its graph forms.

Every interpolation has a **gather form**, ``kernel(coords (3, P), rows (3, S³), size) -> (3, P)``:
integer lattice indices and one 1-D gather per vertex and channel on the planar table
(:func:`~torchgrade.lut.planar_table`). That is what :class:`~torchgrade.LUT3D` runs under autograd,
``torch.compile`` and tracing, and what an ONNX export writes as ``Gather`` nodes. An interpolation
may also have a **whole-frame form** (:class:`EagerForm`), the same interpolation for the eager no-grad
lookup off the CPU from tables derived once per LUT: few operations on the whole frame (on the CPU the operator
``torchgrade::lut_lookup`` runs, :mod:`torchgrade.lut.operator`).
And it may have **grid forms**, one per export backend, ``form(unit (N, 3, H, W) in [0, 1], table
(S, S, S, 3)) -> (N, 3, H, W)`` built on ``grid_sample``, for runtimes that prefer ``GridSample`` (see
:data:`~torchgrade.lut.backends.BACKENDS`).

A new interpolation is one function here plus one :class:`Kernel` line in :data:`KERNELS`; a new
graph form of an existing one is one function plus one entry in its ``grids``.

Examples:
    >>> import torch
    >>> rows = torch.arange(8.0).expand(3, 8)
    >>> KERNELS["trilinear"](torch.full((3, 1), 0.5), rows, 2).flatten().tolist()
    [3.5, 3.5, 3.5]
    >>> KERNELS["trilinear"].graph_form("slices") is trilinear_slices_lookup
    True
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import torch
import torch.nn.functional as F

from ..runtime import constant, device_cached

__all__ = ["Kernel", "EagerForm", "KERNELS", "INTERPOLATIONS", "tetrahedron", "tetrahedral",
           "tetrahedral_tables", "tetrahedral_frame", "trilinear", "trilinear_grid_sample", "strip_table", "trilinear_strip",
           "trilinear_slices_lookup"]


def _cell(coords: torch.Tensor, size: int):
    """Split lattice coordinates ``(3, P)`` in [0, S-1] into the cell's flat int32 base index and the fractions.

    The index is formed in floating point (exact: at most 255³ < 2²⁴) and converted once.
    """
    corner = coords.floor().clamp(max=size - 2)
    fraction = coords - corner
    base = (corner[0] + size * corner[1] + (size * size) * corner[2]).to(torch.int32)
    return base, fraction.unbind(0)


def _tetrahedron_steps(size: int, device) -> torch.Tensor:
    """``(2, 8)`` int32: by order code (:func:`tetrahedron`), the step from ``c000`` to ``v1`` and to ``v2``.

    ``v1`` is one step along the axis of the largest fraction (red on ties with green or blue, green on
    ties with blue); ``v2`` is ``c111`` less one step along the smallest one's (red before green before blue).
    """
    plane = size * size
    diagonal = 1 + size + plane
    steps = []
    for code in range(8):
        r_ge_g, g_ge_b, r_ge_b = code & 4, code & 2, code & 1
        largest = 1 if r_ge_g and r_ge_b else size if not r_ge_g and g_ge_b else plane
        smallest = 1 if not r_ge_g and not r_ge_b else size if r_ge_g and not g_ge_b else plane
        steps.append((largest, diagonal - smallest))
    return torch.tensor(steps, dtype=torch.int32, device=device).t()


def tetrahedron(coords: torch.Tensor, size: int):
    """The tetrahedron of the lattice holding each point ``(3, P)`` in [0, S-1]: 4 flat vertex indices and weights.

    The cube cell is split along its main diagonal into 6 tetrahedra, picked by the order of the
    fractions ``f_a >= f_b >= f_c`` (Kasson, Nin and Plouffe 1995; the scheme OpenColorIO uses). The
    vertices are ``c000``, ``v1`` (a step from ``c000`` along ``a``), ``v2`` (``c111`` less a step
    along ``c``) and ``c111``, with weights ``1 - f_a, f_a - f_b, f_b - f_c, f_c``. The order is one
    code ``4 [f_r >= f_g] + 2 [f_g >= f_b] + [f_r >= f_b]`` that picks the steps from an 8-entry table.

    Returns ``(indices, fractions)``: 4 int32 ``(P,)`` indices into a flattened ``S³`` table and the
    sorted fractions ``(f_a, f_b, f_c)``, each ``(P,)``.

    Examples:
        >>> indices, fractions = tetrahedron(torch.tensor([[0.5], [0.25], [0.0]]), 2)
        >>> [int(i) for i in indices], [float(f) for f in fractions]
        ([0, 1, 3, 7], [0.5, 0.25, 0.0])
    """
    base, (fr, fg, fb) = _cell(coords, size)
    f_max = torch.maximum(torch.maximum(fr, fg), fb)
    f_min = torch.minimum(torch.minimum(fr, fg), fb)
    f_mid = fr + fg + fb - f_max - f_min
    code = (fr >= fg).to(torch.int32) * 4 + (fg >= fb).to(torch.int32) * 2 + (fr >= fb).to(torch.int32)
    steps = _tetrahedron_steps(size, coords.device)
    indices = (base, base + steps[0].index_select(0, code), base + steps[1].index_select(0, code), base + (1 + size + size * size))
    return indices, (f_max, f_mid, f_min)


def tetrahedral(coords: torch.Tensor, table: torch.Tensor, size: int) -> torch.Tensor:
    """Tetrahedral interpolation of a planar table ``(3, S³)`` at lattice coordinates ``(3, P)`` -> ``(3, P)``.

    ``y = c000 + f_a (v1 - c000) + f_b (v2 - v1) + f_c (c111 - v2)`` over the vertices and sorted
    fractions of :func:`tetrahedron` (the weights ``1 - f_a, f_a - f_b, f_b - f_c, f_c`` in difference
    form, so a constant table gives its constant exactly): exact on lattice points and continuous
    across cells; on ties the ambiguous vertex gets weight 0. One gather of the three table rows per
    vertex (``index_select``, an ONNX ``Gather``), so ``torch.compile`` fuses it into a single pass.

    Examples:
        >>> rows = torch.arange(8.0).expand(3, 8)
        >>> tetrahedral(torch.tensor([[1.0], [0.0], [1.0]]), rows, 2).flatten().tolist()
        [5.0, 5.0, 5.0]
    """
    indices, (f_max, f_mid, f_min) = tetrahedron(coords, size)

    def channel(row: torch.Tensor) -> torch.Tensor:
        c000, v1, v2, c111 = (row.index_select(0, index) for index in indices)
        return c000 + f_max * (v1 - c000) + f_mid * (v2 - v1) + f_min * (c111 - v2)

    return torch.stack([channel(row) for row in table.unbind(0)])


def tetrahedral_tables(rows: torch.Tensor, size: int) -> torch.Tensor:
    """What :func:`tetrahedral_frame` gathers from, derived once per table from the planar rows ``(3, S³)``.

    ``(3, 4 S³ + S + 1)``: channel ``c`` holds the values ``v``, then the steps ``v[i + 1] - v[i]``
    (red), ``v[i + S] - v[i]`` (green) and ``v[i + S²] - v[i]`` (blue) by flat index ``i``, 0 where the
    step leaves the lattice (read only with weight 0), then ``S + 1`` zeros (the same).

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> from torchgrade.lut.lattice import planar_table
        >>> tables = tetrahedral_tables(planar_table(identity_table(2)), 2)
        >>> tables.shape, tables[0, :8].tolist(), tables[0, 8:16].tolist()
        (torch.Size([3, 35]), [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0], [1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0])
    """
    cells = size ** 3
    tables = rows.new_zeros(3, 4 * cells + size + 1)
    steps = tables[:, :4 * cells].view(3, 4, cells)
    steps[:, 0] = rows
    for axis, step in enumerate((1, size, size * size), start=1):
        torch.sub(rows[:, step:], rows[:, :-step], out=steps[:, axis, :-step])
        steps[:, axis].view(3, size, size, size).select(4 - axis, size - 1).zero_()  # [c, b, g, r]: the axis' last plane
    return tables


def _walk_matrix(size: int) -> list:
    """The flat indices of :func:`tetrahedral_frame`'s 4 gathers as rows of coefficients of the terms ``(corner r, g, b,
    [f_r >= f_g], [f_g >= f_b], [f_r >= f_b], 1)``: the values at ``c000``, then each axis' steps at ``c000`` plus the
    steps of the axes ranked above it (a larger fraction; red before green before blue on ties, the order
    :func:`tetrahedron` picks vertices in), each table of :func:`tetrahedral_tables` ``S³`` entries after the last.

    Examples:
        >>> _walk_matrix(2)[3]
        [1, 2, 4, 0, 2, 1, 24]
    """
    cells, plane = size ** 3, size * size
    return [[1, size, plane, 0, 0, 0, 0],
            [1, size, plane, -size, 0, -plane, cells + size + plane],
            [1, size, plane, 1, -plane, 0, 2 * cells + plane],
            [1, size, plane, 0, size, 1, 3 * cells]]


def tetrahedral_frame(coords: torch.Tensor, tables: torch.Tensor, size: int) -> torch.Tensor:
    """:func:`tetrahedral` at lattice coordinates ``(3, P)`` of a whole frame -> ``(3, P)``, without autograd: the eager
    form off the CPU, where a frame is one pass (a GPU), 13 operations.

    The tetrahedron and vertex differences of :func:`tetrahedral`, without sorting the fractions: the walk c000 -> v1
    -> v2 -> c111 steps once along each axis, largest fraction first, so ``y = v[c000] + f_r Δr[p_r] + f_g Δg[p_g] +
    f_b Δb[p_b]`` where ``p_k`` is c000 plus the steps of the axes ranked above ``k``: the terms of :func:`tetrahedral`,
    summed in r, g, b order instead of by size (the two agree to float rounding). The corner is not clamped to
    ``S - 2``: at the lattice's top face the fraction is 0, and the step tables' zeros and padding keep the indices
    inside ``tables`` (:func:`tetrahedral_tables`). The flat indices are formed without a matrix product: one product
    and one sum give ``c000`` and the order code ``4 [f_r >= f_g] +
    2 [f_g >= f_b] + [f_r >= f_b]``, which picks the 4 offsets from a table of 8 (:func:`_walk_offsets`). Every value
    is an integer below 2²⁴, so each step is exact in float32 whatever precision the device gives a matrix product
    (a GPU's TF32 would round the indices). One gather takes the 12 entries a pixel from the three channels' tables.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> from torchgrade.lut.lattice import planar_table
        >>> tables = tetrahedral_tables(planar_table(identity_table(3)), 3)
        >>> tetrahedral_frame(torch.tensor([[1.5], [0.25], [2.0]]), tables, 3).flatten().tolist()
        [0.75, 0.125, 1.0]
    """
    points = coords.shape[-1]
    terms = coords.new_empty(6, points)  # corner r, g, b; [f_r >= f_g], [f_g >= f_b], [f_r >= f_b]
    corner = torch.floor(coords, out=terms[:3])
    fraction = coords - corner
    torch.ge(fraction[:2], fraction[1:], out=terms[3:5])
    torch.ge(fraction[0], fraction[2], out=terms[5])
    weights = constant(((1.0,), (size,), (size * size,), (4.0,), (2.0,), (1.0,)), coords)
    corner_index, code = (terms * weights).view(2, 3, points).sum(1).to(torch.int32)
    index = _walk_offsets(size, coords.device).index_select(1, code).add_(corner_index)
    values, red, green, blue = tables.index_select(1, index.view(-1)).view(3, 4, points).unbind(1)
    f_r, f_g, f_b = fraction
    return torch.addcmul(values, red, f_r).addcmul_(green, f_g).addcmul_(blue, f_b)


@device_cached
def _walk_offsets(size: int, device: torch.device) -> torch.Tensor:
    """``(4, 8)`` int32: by order code (:func:`tetrahedral_frame`), each gather's flat index less ``c000``, from the
    rows of :func:`_walk_matrix`.

    Examples:
        >>> _walk_offsets(2, torch.device("cpu"))[:, 7].tolist()  # equal fractions: v at c000, then Δr, Δg, Δb along the walk r, g, b
        [0, 8, 17, 27]
    """
    codes = [((code >> 2) & 1, (code >> 1) & 1, code & 1) for code in range(8)]
    offsets = [[row[3] * a + row[4] * b + row[5] * c + row[6] for a, b, c in codes] for row in _walk_matrix(size)]
    return torch.tensor(offsets, dtype=torch.int32, device=device)


def trilinear(coords: torch.Tensor, table: torch.Tensor, size: int) -> torch.Tensor:
    """Trilinear interpolation of a planar table ``(3, S³)`` at lattice coordinates ``(3, P)`` -> ``(3, P)``.

    ``y = lerp_b(lerp_g(lerp_r(c000, c100), lerp_r(c010, c110)), lerp_g(...))`` over the 8 corners,
    one 1-D gather per corner and table row as in :func:`tetrahedral`.

    Examples:
        >>> rows = torch.arange(8.0).expand(3, 8)
        >>> trilinear(torch.tensor([[0.5], [0.0], [0.0]]), rows, 2).flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    base, (fr, fg, fb) = _cell(coords, size)

    def channel(row: torch.Tensor) -> torch.Tensor:
        def lerp_r(index):
            low = row.index_select(0, index)
            return low + fr * (row.index_select(0, index + 1) - low)

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

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> trilinear_grid_sample(torch.full((1, 3, 1, 1), 0.25), identity_table(3)).flatten().tolist()
        [0.25, 0.25, 0.25]
    """
    volume = table.permute(3, 0, 1, 2).unsqueeze(0).expand(unit.shape[0], -1, -1, -1, -1)
    grid = (unit * 2.0 - 1.0).permute(0, 2, 3, 1).unsqueeze(1)
    return F.grid_sample(volume, grid, mode="bilinear", padding_mode="border", align_corners=True).squeeze(2)


def strip_table(table: torch.Tensor) -> torch.Tensor:
    """A ``(S, S, S, 3)`` table ``[b, g, r]`` as a ``(1, 3, S, S²)`` strip image: row ``g``, column ``b·S + r``.

    Examples:
        >>> strip_table(torch.zeros(5, 5, 5, 3)).shape
        torch.Size([1, 3, 5, 25])
    """
    size = table.shape[0]
    return table.permute(3, 1, 0, 2).reshape(1, 3, size, size * size)


def trilinear_strip(unit: torch.Tensor, strip: torch.Tensor) -> torch.Tensor:
    """Trilinear lookup of ``unit`` ``(N, 3, H, W)`` in [0, 1] with two 4-D ``grid_sample``s on a strip.

    Bilinear sampling at column ``b0·S + r``, row ``g`` interpolates red and green inside blue slice
    ``b0`` (red never crosses into the next slice: at ``r = S - 1`` its neighbour has weight 0);
    the two slices around ``b`` are then blended. ``align_corners=True`` puts -1 and +1 on the
    centres of the first and last texels, so lattice points are sampled exactly. 4-D GridSample
    exports at opset 16, which OpenVINO and TensorRT accept.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> strip = strip_table(identity_table(3))
        >>> trilinear_strip(torch.full((1, 3, 1, 1), 0.75), strip).flatten().tolist()
        [0.75, 0.75, 0.75]
    """
    size = strip.shape[-2]
    n, _, height, width = unit.shape
    r, g, b = (unit * (size - 1)).unbind(1)
    low_slice = b.floor().clamp(max=size - 2)
    blend = (b - low_slice).unsqueeze(1)
    rows = g / (size - 1) * 2.0 - 1.0
    columns = (low_slice * size + r) / (size * size - 1) * 2.0 - 1.0
    step = 2.0 * size / (size * size - 1)

    def sample(x):
        grid = torch.stack((x, rows), dim=-1).reshape(1, n * height, width, 2)
        values = F.grid_sample(strip, grid, mode="bilinear", padding_mode="border", align_corners=True)
        return values.reshape(3, n, height, width).transpose(0, 1)

    low = sample(columns)
    return low + blend * (sample(columns + step) - low)


def trilinear_slices_lookup(unit: torch.Tensor, table: torch.Tensor) -> torch.Tensor:
    """:func:`trilinear_strip` on a ``(S, S, S, 3)`` table laid out as its blue slices side by side (:func:`strip_table`),
    the ``"slices"`` graph form.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> trilinear_slices_lookup(torch.full((1, 3, 1, 1), 0.5), identity_table(3)).flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    return trilinear_strip(unit, strip_table(table))


@dataclass(frozen=True)
class EagerForm:
    """An interpolation's whole-frame form for the eager no-grad lookup off the CPU, for lattices up to ``max_size``:
    ``tables(rows, size)`` once per table, then ``frame(coords, tables, size)`` on the whole frame's lattice
    coordinates ``(3, P)`` (:func:`tetrahedral_frame`).

    Examples:
        >>> KERNELS["tetrahedral"].eager.max_size
        65
    """

    tables: Callable[[torch.Tensor, int], torch.Tensor]
    frame: Callable[[torch.Tensor, torch.Tensor, int], torch.Tensor]
    max_size: int


@dataclass(frozen=True)
class Kernel:
    """One interpolation: its ``gather`` form (called by ``kernel(coords, rows, size)``), its ``grids`` by
    backend and its whole-frame ``eager`` form (or ``None``: the eager lookup off the CPU runs the gather form). On the
    CPU the operator ``torchgrade::lut_lookup`` runs every interpolation (:mod:`torchgrade.lut.operator`).

    Examples:
        >>> KERNELS["tetrahedral"].graph_form("slices") is None
        True
    """

    gather: Callable[[torch.Tensor, torch.Tensor, int], torch.Tensor]
    grids: dict = field(default_factory=dict)
    eager: Optional[EagerForm] = None

    def __call__(self, coords: torch.Tensor, rows: torch.Tensor, size: int) -> torch.Tensor:
        return self.gather(coords, rows, size)

    @property
    def whole_frame(self) -> EagerForm:
        """The whole-frame form, for a caller that checked there is one
        (:func:`~torchgrade.lut.apply.whole_frame_tables`); ``ValueError`` where there is none."""
        if self.eager is None:
            raise ValueError(f"{self.gather.__name__} has no whole-frame form")
        return self.eager

    def graph_form(self, backend: str) -> Optional[Callable[[torch.Tensor, torch.Tensor], torch.Tensor]]:
        """The grid form an export with ``backend`` uses, or ``None`` to export the gather form."""
        return self.grids.get(backend)


KERNELS = {
    "trilinear": Kernel(trilinear, {"slices": trilinear_slices_lookup, "volume": trilinear_grid_sample}),
    # Up to 65³: the tables are 4 times the planar table (13 MiB at 65³; 4 S³ < 2²⁴ keeps the index product exact).
    "tetrahedral": Kernel(tetrahedral, eager=EagerForm(tetrahedral_tables, tetrahedral_frame, max_size=65)),
}
"""The interpolations by name, what ``LUT3D(...)(image, interpolation)`` takes. The C loop of the operator
``torchgrade::lut_lookup`` (``lookup.c``) has one loop for each."""

INTERPOLATIONS = tuple(KERNELS)
