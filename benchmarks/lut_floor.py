"""The floor of a 33³ LUT's error: how close can *any* table, however its entries are chosen, come to a look?

``bench_lut.py`` measures LUTs baked the usual way, by sampling the look at the lattice points. This
asks what the best possible table on the same lattice would do on the same pixels. With the lattice
(shaper and domain) and the interpolation fixed, each pixel's lookup is a fixed linear combination of
table entries (4 for tetrahedral, 8 for trilinear), and its displayed 8-bit code is within ``t`` of
direct evaluation exactly when the lookup lies in an interval (open-ended where the display's clip
to [0, 1] hides the error). "Is there a table within ``t`` of every pixel?" is therefore a linear
feasibility problem, solved with SciPy's HiGHS one channel at a time (channels share no entries) as
an elastic program that also returns the table that comes closest (:func:`elastic_fit`):

* **Lowest max error, sRGB-encoded entries** (:func:`lowest_max_error`): bisection on ``t`` from the
  max bar of 4 codes. Infeasible ``t`` are lower bounds; every table found is an upper bound.
  Entries range over [-1, 2] in table units (:data:`ENTRY_RANGE`): a whole display range beyond either end.
* **Any table within 4 codes, linear entries**: the same question for entries stored linear.
* **The 99.9th percentile** is a count, not a linear program. Where a table within 4 codes exists,
  :func:`l1_table_share_over` finds one by minimising the summed excess over 1 code: if it leaves at
  most 0.1 % of values above 1 code, a table within the whole bar exists on these pixels; if more,
  that share is only an upper bound on the smallest one.

Where the lower bound reaches 4 codes, no bake, fit or cleverer choice of entries in that range keeps the image
within a max-error bar of 4 on that lattice (on every 4th pixel, hence on the whole image).

Pixels: every 4th pixel of Desk, CandleGlass and GoldenGate, as in ``bench_lut.py``. Looks: the strong
look (contrast 30, saturation 20, temperature 20, ACES tone mapping) graded in linear Rec.709, as the
accuracy tests do, and graded in ACEScc/ACEScg (``ColorGrade(aces=True)``) as Unity does with ACES.
Lattices: 33³ LogC on the two domains ``bake_lut`` offers, the default (black to 58.86, the
document's) and the scene's range (black to the image's largest value, ``bake_lut(scene=image)``),
then, on Desk, lattices whose bottom is raised above black. Lookups are taken in float64.

Run: ``.venv/bin/python -m benchmarks lut_floor [--out DIR]`` (two worker processes, about 25 minutes on two cores;
writes lut_floor.json and .md to ``--out``, default benchmarks/out; the committed ones with ``--out benchmarks/results``,
which benchmarks/bench_lut_fit.py reads).
"""

from __future__ import annotations

import functools
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import scipy
import torch
from scipy.optimize import linprog
from scipy.sparse import csr_matrix, hstack, vstack
from tqdm import tqdm

from benchmarks.common import argument_parser, write_results
from benchmarks.bench_lut import ACCURACY_IMAGES, SIZE, accuracy_image, strong_look
from benchmarks.metrics import srgb_codes
from torchgrade.color import linear_to_logc, srgb_to_linear
from torchgrade.lut import DEFAULT_DOMAINS, INTERPOLATIONS, bake_lut
from torchgrade.lut.shapers import lattice_unit
from torchgrade.lut.bake import scene_domain
from torchgrade.lut.kernels import tetrahedral, trilinear

ROOT = Path(__file__).resolve().parents[1]

COMMAND = ".venv/bin/python -m benchmarks lut_floor"
MAX_BAR, P999_BAR = 4.0, 1.0
"""The accuracy bar, 8-bit codes: max error, and error at the 99.9th percentile."""
FEASIBLE = 1e-6
"""Largest :func:`smallest_violation` (table units) read as 0: HiGHS's tolerances are 1e-7."""
TIME_LIMIT_S = 600
"""HiGHS time limit per problem; a problem that hits it is reported as undecided."""
NUMERICAL_DIFFICULTIES = 4
"""``linprog`` status when HiGHS's simplex stops on numerical trouble; its interior-point method is tried then."""
ENTRY_RANGE = (-1.0, 2.0)
"""Table entries the programs may choose, in table units: one display range beyond either end. Unbounded, HiGHS meets
the constraints with entries of ±1e17 that cancel, within its scaled tolerances but displaying 255 codes off. On Desk's
default lattice, widening the range to [-50, 51] changes the violations by at most 1.1e-7 (HiGHS's tolerance)."""
FLOOR_RESOLUTION = 0.1
"""How close, in 8-bit codes, :func:`lowest_max_error` brings its lower and upper bounds."""
LOOKS = {"Rec.709": False, "ACEScc/ACEScg": True}
"""Where the strong look grades: name -> ``ColorGrade(aces=...)``."""
DOMAINS = ("default", "scene")
SWEEP_IMAGE = "Desk"
SWEEP_BOTTOMS = (0.005, 0.01, 0.02)
"""Linear values at the bottom of the lattice in the sweep, beside black (its top is the scene's largest value)."""
LIBRARY_KERNELS = {"trilinear": trilinear, "tetrahedral": tetrahedral}
"""The library's lookups that :func:`interpolation_matrix` checks its weights against."""


def vertex_weights(coords: torch.Tensor, size: int, interpolation: str) -> tuple:
    """Flat table indices and weights of each pixel's lookup, ``(P, k)`` numpy arrays (k = 4 or 8).

    ``coords`` ``(3, P)`` are lattice coordinates in [0, size - 1]; the formulas are those of
    :func:`torchgrade.lut.tetrahedral` and :func:`torchgrade.lut.trilinear` (checked against them by
    :func:`interpolation_matrix`). Index ``r + S g + S² b``.
    """
    corner = coords.floor().clamp(max=size - 2)
    fraction = (coords - corner).t().numpy()  # (P, 3): r, g, b
    base = (corner[0] + size * corner[1] + size * size * corner[2]).long().numpy()
    strides = np.array([1, size, size * size])
    if interpolation == "trilinear":
        offsets = np.array([[dr, dg, db] for db in (0, 1) for dg in (0, 1) for dr in (0, 1)])  # (8, 3)
        weights = np.prod(np.where(offsets[None] == 1, fraction[:, None], 1.0 - fraction[:, None]), axis=2)
        return base[:, None] + offsets @ strides, weights
    order = np.argsort(-fraction, axis=1, kind="stable")  # axes by decreasing fraction
    f_max, f_mid, f_min = np.take_along_axis(fraction, order, axis=1).T
    first = strides[order[:, 0]]
    second = first + strides[order[:, 1]]
    index = np.stack([base, base + first, base + second, base + strides.sum()], axis=1)
    weights = np.stack([1.0 - f_max, f_max - f_mid, f_mid - f_min, f_min], axis=1)
    return index, weights


def interpolation_matrix(coords: torch.Tensor, size: int, interpolation: str) -> csr_matrix:
    """The ``(P, size³)`` matrix ``A`` with ``lookup = A @ table_column``, checked against the library's kernel."""
    index, weights = vertex_weights(coords, size, interpolation)
    rows = np.repeat(np.arange(index.shape[0]), index.shape[1])
    matrix = csr_matrix((weights.ravel(), (rows, index.ravel())), shape=(index.shape[0], size**3))
    matrix.eliminate_zeros()  # an entry is read only where its weight is not 0
    table = torch.rand(3, size**3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    library = LIBRARY_KERNELS[interpolation](coords, table, size).numpy()
    mismatch = np.abs(matrix @ table.numpy().T - library.T).max()
    if mismatch > 1e-9:
        raise AssertionError(f"{interpolation} weights differ from the library's kernel by {mismatch}")
    return matrix


def entry_interval(codes: np.ndarray, t: float, encoding: str) -> tuple:
    """Lookups whose displayed code is within ``t`` of ``codes``: ``(low, high)``, ±inf where the clip hides the error.

    Entries decode to linear (identity, or sRGB decoding) and display as ``255 srgb(clamp(., 0, 1))``.
    """

    def table_value(code):
        unit = torch.from_numpy(np.clip(code, 0.0, 255.0) / 255.0)
        return (unit if encoding == "srgb" else srgb_to_linear(unit)).numpy()

    low = np.where(codes - t <= 0.0, -np.inf, table_value(codes - t))
    high = np.where(codes + t >= 255.0, np.inf, table_value(codes + t))
    return low, high


def _interval_rows(matrix: csr_matrix, low: np.ndarray, high: np.ndarray) -> tuple:
    """``low <= A v <= high`` as ``rows @ v <= limits``, leaving out the infinite sides; also which pixels each row is."""
    above, below = np.isfinite(high), np.isfinite(low)
    rows = vstack([matrix[above], -matrix[below]]).tocsr()
    pixels = np.concatenate([np.flatnonzero(above), np.flatnonzero(below)])
    return rows, np.concatenate([high[above], -low[below]]), pixels


def _entry_bounds(matrix: csr_matrix) -> list:
    """Bounds of the table entries: :data:`ENTRY_RANGE` where some pixel reads the entry, fixed at 0 elsewhere."""
    used = np.zeros(matrix.shape[1], dtype=bool)
    used[matrix.indices] = True
    return [ENTRY_RANGE if u else (0.0, 0.0) for u in used]


def _solve(cost, constraints, limits, bounds):
    """``linprog`` with HiGHS (its choice of method, then interior point if that hits numerical trouble); None without an optimum."""
    for method in ("highs", "highs-ipm"):
        result = linprog(cost, A_ub=constraints, b_ub=limits, bounds=bounds, method=method, options={"time_limit": TIME_LIMIT_S})
        if result.status != NUMERICAL_DIFFICULTIES:
            break
    return result if result.status == 0 else None


def elastic_fit(matrix: csr_matrix, codes: np.ndarray, t: float, encoding: str):
    """The table column that leaves the pixels' intervals (:func:`entry_interval`) by the least, and by how much.

    The elastic linear program ``min s`` subject to ``low - s <= A v <= high + s``, ``s >= 0``: always
    feasible, so HiGHS answers with a number instead of a verdict. ``s = 0`` means the column keeps every
    pixel within ``t`` codes. Entries no pixel reads are fixed at 0. Returns ``(s, v)`` in table units, or
    None if HiGHS stops without an optimum.
    """
    rows, limits, _ = _interval_rows(matrix, *entry_interval(codes, t, encoding))
    constraints = hstack([rows, csr_matrix(-np.ones((rows.shape[0], 1)))]).tocsr()
    cost = np.zeros(matrix.shape[1] + 1)
    cost[-1] = 1.0
    result = _solve(cost, constraints, limits, _entry_bounds(matrix) + [(0.0, None)])
    return None if result is None else (float(result.fun), result.x[:-1])


def smallest_violation(matrix: csr_matrix, codes: np.ndarray, t: float, encoding: str):
    """``s`` of :func:`elastic_fit`: 0 when a column within ``t`` codes of every pixel exists; None if undecided."""
    fit = elastic_fit(matrix, codes, t, encoding)
    return None if fit is None else fit[0]


def channel_violations(matrix: csr_matrix, codes: np.ndarray, t: float, encoding: str) -> list:
    """:func:`smallest_violation` of each channel of ``codes`` ``(3, P)`` (channels share no table entries)."""
    return [smallest_violation(matrix, channel, t, encoding) for channel in codes]


def table_exists(violations: list):
    """True when every channel's :func:`smallest_violation` is 0 (within HiGHS's tolerances), False when one is
    not, None when a channel is undecided and none is known to fail."""
    if any(v is not None and v > FEASIBLE for v in violations):
        return False
    return None if None in violations else True


def displayed_error(matrix: csr_matrix, column: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Per-pixel error in 8-bit codes of a column of sRGB-encoded entries: ``|255 clip(A v, 0, 1) - code|``."""
    return np.abs(255.0 * np.clip(matrix @ column, 0.0, 1.0) - codes)


def lowest_max_error(matrix: csr_matrix, codes: np.ndarray, resolution: float = FLOOR_RESOLUTION):
    """Bounds ``(lower, upper)`` on the smallest max error, in 8-bit codes, that any table with sRGB-encoded entries
    in :data:`ENTRY_RANGE` reaches on ``codes`` ``(3, P)``; None if HiGHS leaves a step undecided.

    Bisection on the bar ``t``, starting at :data:`MAX_BAR`: no table is within ``t`` when some channel's
    :func:`elastic_fit` leaves its intervals (then ``lower = t``). Channels share no entries, so the best column
    found for each channel makes a table whose :func:`displayed_error` bounds the floor from above. Stops when
    the bounds are ``resolution`` apart. ``lower >= MAX_BAR`` is the exact verdict that no table keeps every
    pixel within the max bar.
    """
    channels = list(np.asarray(codes, dtype=np.float64))
    best = [math.inf] * len(channels)  # each channel's smallest max error found so far
    lower, t = 0.0, MAX_BAR
    order = list(range(len(channels)))  # the channel that failed last is asked first
    while max(best) - lower > resolution:
        for c in order:
            fit = elastic_fit(matrix, channels[c], t, "srgb")
            if fit is None:
                return None
            violation, column = fit
            best[c] = min(best[c], float(displayed_error(matrix, column, channels[c]).max()))
            if violation > FEASIBLE:
                lower = t
                order.remove(c)
                order.insert(0, c)
                if math.isfinite(max(best)):  # the verdict at t is all this step needs
                    break
        t = (lower + max(best)) / 2.0
    return lower, max(best)


def l1_table_share_over(matrix: csr_matrix, codes: np.ndarray, inner: float = P999_BAR, outer: float = MAX_BAR):
    """Share of values a table found by L1 leaves more than ``inner`` codes off (sRGB entries); None if HiGHS finds none.

    Per channel, the linear program ``min sum(e)`` over entries ``v`` and excesses ``e >= 0`` with
    ``A v`` within ``outer`` codes of every pixel and within ``inner`` codes plus ``e``: the convex
    stand-in for "fewest values above ``inner``", so the share is an upper bound on the smallest share
    among tables within ``outer``. Ask only where such a table exists (:func:`lowest_max_error`).
    """
    channels = np.asarray(codes, dtype=np.float64)
    over = 0
    pixels = matrix.shape[0]
    for channel in channels:
        inner_rows, inner_limits, rows_pixel = _interval_rows(matrix, *entry_interval(channel, inner, "srgb"))
        outer_rows, outer_limits, _ = _interval_rows(matrix, *entry_interval(channel, outer, "srgb"))
        excess = csr_matrix((-np.ones(len(rows_pixel)), (np.arange(len(rows_pixel)), rows_pixel)), shape=(len(rows_pixel), pixels))
        constraints = vstack([hstack([inner_rows, excess]), hstack([outer_rows, csr_matrix((outer_rows.shape[0], pixels))])]).tocsr()
        cost = np.concatenate([np.zeros(matrix.shape[1]), np.ones(pixels)])
        result = _solve(cost, constraints, np.concatenate([inner_limits, outer_limits]), _entry_bounds(matrix) + [(0.0, None)] * pixels)
        if result is None:
            return None
        over += int((displayed_error(matrix, result.x[: matrix.shape[1]], channel) > inner + 255.0 * FEASIBLE).sum())
    return over / channels.size


@functools.lru_cache(maxsize=None)
def measured_scene(name: str, aces: bool) -> tuple:
    """An accuracy image, its strong look graded per ``aces``, and the look's direct 8-bit codes ``(3, P)``."""
    image = accuracy_image(name)
    look = strong_look(aces)
    with torch.no_grad():
        direct = srgb_codes(look(image.double())).reshape(3, -1).numpy()
    return image, look, direct


def lattice_domain(image: torch.Tensor, domain: str, bottom: float = 0.0) -> tuple:
    """A LogC lattice domain in code values, from linear ``bottom`` (black by default) to the top of ``domain``:
    ``"default"`` (58.86) or ``"scene"`` (the image's largest value)."""
    _, high = DEFAULT_DOMAINS["logc"] if domain == "default" else scene_domain(image, "logc")
    return float(linear_to_logc(torch.tensor(bottom, dtype=torch.float64))), high  # LogC of black is both domains' bottom


def baked_errors(look, image: torch.Tensor, direct: np.ndarray, lattice: tuple, interpolation: str) -> np.ndarray:
    """Errors in 8-bit codes ``(3, P)`` of the LUT ``bake_lut`` samples on ``lattice`` (sRGB entries)."""
    with torch.no_grad():
        lut = bake_lut(look, size=SIZE, shaper="logc", domain=lattice, output_encoding="srgb")
        return np.abs(srgb_codes(lut(image, interpolation)).reshape(3, -1).numpy() - direct)


def floor_row(name: str, look_name: str, domain: str, interpolation: str, bottom: float = 0.0) -> dict:
    """Every answer for one lattice on one image: the baked LUT's errors; bounds on the lowest max error of any
    table (:func:`lowest_max_error`); whether a table with linear entries stays within :data:`MAX_BAR`; and, where
    some table does, the L1 table's share of values above :data:`P999_BAR` (:func:`l1_table_share_over`)."""
    start = time.perf_counter()
    image, look, direct = measured_scene(name, LOOKS[look_name])
    lattice = lattice_domain(image, domain, bottom)
    error = baked_errors(look, image, direct, lattice, interpolation)
    points = image.double().reshape(3, -1)
    matrix = interpolation_matrix(lattice_unit(points, "logc", *lattice) * (SIZE - 1), SIZE, interpolation)
    floor = lowest_max_error(matrix, direct)
    reachable = floor is not None and floor[0] < MAX_BAR
    violations = channel_violations(matrix, direct, MAX_BAR, "linear")
    return {"image": name, "look": look_name, "domain": domain, "bottom": bottom, "top": float(points.max()) if domain == "scene" else None,
            "interpolation": interpolation, "baked_p99_9": float(np.quantile(error, 0.999)), "baked_max": float(error.max()),
            "lowest_max": floor, "linear_within_max_bar": {"table_exists": table_exists(violations), "violation": violations},
            "l1_share_over_p999_bar": l1_table_share_over(matrix, direct) if reachable else None, "seconds": time.perf_counter() - start}


def tasks() -> list:
    """Arguments of every :func:`floor_row`: both lattices on every image, look and interpolation, then the sweep of the bottom."""
    main = [(n, k, d, i) for n in ACCURACY_IMAGES for k in LOOKS for d in DOMAINS for i in INTERPOLATIONS]
    return main + [(SWEEP_IMAGE, "Rec.709", "scene", i, b) for b in SWEEP_BOTTOMS for i in INTERPOLATIONS]


def _row(arguments: tuple) -> dict:
    return floor_row(*arguments)


def _floor(row: dict) -> str:
    floor = row["lowest_max"]
    return "undecided" if floor is None else f"{floor[0]:.2f}–{floor[1]:.2f}"


def _share(row: dict) -> str:
    """The L1 column: the L1 table's share above 1 code, or why there is none."""
    if row["lowest_max"] is not None and row["lowest_max"][0] >= MAX_BAR:
        return f"no table within {MAX_BAR:g}"
    share = row["l1_share_over_p999_bar"]
    return "undecided" if share is None else f"{100 * share:.2f} %"


def markdown(report: dict) -> str:
    answer = {True: "yes", False: "**no**", None: "undecided"}
    main = [r for r in report["rows"] if r["bottom"] == 0.0]
    sweep = [r for r in report["rows"] if r["image"] == SWEEP_IMAGE and r["look"] == "Rec.709" and r["domain"] == "scene"]
    lines = [
        f"# How close can any {SIZE}³ LogC table come to the strong look? (linear programming, every 4th pixel)",
        "",
        f"The look: contrast 30, saturation 20, temperature 20, ACES tone mapping, graded in Rec.709 or in ACEScc/ACEScg. "
        f"The bar: p99.9 within {P999_BAR:g} and max within {MAX_BAR:g} 8-bit sRGB codes of direct evaluation. Baked: the LUT "
        "`bake_lut` samples (sRGB entries). Lowest max: bounds on the smallest max error any table with sRGB entries can "
        f"reach on these pixels, whatever its entries in [{ENTRY_RANGE[0]:g}, {ENTRY_RANGE[1]:g}] (HiGHS, bisection to {FLOOR_RESOLUTION:g} code); a lower bound of "
        f"{MAX_BAR:g} or more means no table is within the max bar. Linear entries: does any table with linear entries keep "
        f"every pixel within {MAX_BAR:g}. L1 table: where some table is within {MAX_BAR:g}, the share of values that the table "
        f"found by L1 (least summed excess over {P999_BAR:g} code, every value within {MAX_BAR:g}) leaves above {P999_BAR:g} "
        f"code; 0.1 % or less proves a table within the whole bar exists on these pixels, more is an upper bound, not a floor. "
        "Lattice default: LogC from black to 58.86; scene: from black to the image's largest value. No table within a bar "
        "on every 4th pixel means none on the whole image either.",
        "",
        "| image | look | lattice | interpolation | baked p99.9 | baked max | lowest max, any table | any table within 4, linear entries | L1 table: values above 1 code |",
        "| --- | --- | --- | --- | ---: | ---: | ---: | --- | ---: |",
    ]
    for r in main:
        lattice = r["domain"] if r["top"] is None else f"scene (to {r['top']:.0f})"
        lines.append(
            f"| {r['image']} | {r['look']} | {lattice} | {r['interpolation']} | {r['baked_p99_9']:.2f} | {r['baked_max']:.1f} | "
            f"{_floor(r)} | {answer[r['linear_within_max_bar']['table_exists']]} | {_share(r)} |"
        )
    lines += [
        "",
        f"## {SWEEP_IMAGE}: the lattice's bottom (Rec.709 grade, sRGB entries, top at the scene's largest value)",
        "",
        "Raising the bottom above black spends the lattice where the look still changes: contrast 30 maps inputs below "
        "about 0.01 to within half a code of black.",
        "",
        "| bottom (linear) | interpolation | baked p99.9 | baked max | lowest max, any table | any table within 4, linear entries | L1 table: values above 1 code |",
        "| ---: | --- | ---: | ---: | ---: | --- | ---: |",
    ]
    for r in sweep:
        lines.append(
            f"| {r['bottom']:g} | {r['interpolation']} | {r['baked_p99_9']:.2f} | {r['baked_max']:.1f} | {_floor(r)} | "
            f"{answer[r['linear_within_max_bar']['table_exists']]} | {_share(r)} |"
        )
    lines += ["", f"Reproduce: `{report['command']}`", ""]
    return "\n".join(lines)


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    work = tasks()
    with ProcessPoolExecutor(max_workers=2) as pool:
        rows = list(tqdm(pool.map(_row, work), total=len(work), desc="lattices", unit="lattice"))
    report = {"command": COMMAND, "size": SIZE, "scipy": scipy.__version__, "torch": torch.__version__, "rows": rows}
    write_results(args.out, "lut_floor", report, markdown(report).splitlines(), COMMAND)


if __name__ == "__main__":
    main()
