"""The floor of a 33³ LUT's error: can *any* table, however its entries are chosen, meet an accuracy bar?

``bench_lut.py`` measures LUTs baked the usual way, by sampling the look at the lattice points. This
asks what the best possible table of the same lattice would do on the same pixels. For a LogC LUT
on the default domain with a given interpolation, each pixel's lookup is a fixed linear combination
of table entries (4 for tetrahedral, 8 for trilinear), and its displayed 8-bit sRGB code stays
within ``t`` of direct evaluation exactly when that combination lies in an interval of table values
(the display's clip to [0, 1] makes the interval open-ended near black and white). "Is there a table
whose error is at most ``t`` on every pixel?" is therefore a linear feasibility problem, solved here
with SciPy's HiGHS, one channel at a time (channels share no entries), for both output encodings.

``t = 4`` is the max-error bar; ``t = 1`` on every pixel is sufficient, not necessary, for a p99.9
within 1 code. When no table has max error ≤ 4 on these pixels, no bake, fit or cleverer choice of
entries can meet a max-error bar of 4 on the image. The last column asks again without the pixels
that have a channel above the lattice's top (the lookup clamps them to it, while the look keeps
changing): where only that column says yes, those pixels are what no table can serve.

The pixels, look and lattice are those of the accuracy table in ``bench_lut.py`` (every 4th pixel
of Desk, CandleGlass and GoldenGate; contrast 30, saturation 20, temperature 20, ACES; 33³, LogC up
to 58.86). Lookups are taken in float64 at the pixels' lattice coordinates.

Run: ``.venv/bin/python benchmarks/lut_floor.py`` (writes benchmarks/results/lut_floor.json and .md).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
from scipy.optimize import linprog
from scipy.sparse import csr_matrix, hstack, vstack

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_lut import ACCURACY_IMAGES, SIZE, accuracy_image, strong_look  # noqa: E402
from benchmarks.metrics import srgb_codes  # noqa: E402
from torchgrade.color import srgb_to_linear  # noqa: E402
from torchgrade.lut import DEFAULT_DOMAINS, INTERPOLATIONS, OUTPUT_ENCODINGS, _KERNELS, bake_lut, lattice_unit, shaper_decode  # noqa: E402

COMMAND = ".venv/bin/python benchmarks/lut_floor.py"
MAX_BAR = 4.0
"""The max-error bar, 8-bit codes."""
BARS = (MAX_BAR, 1.0)
"""Max errors asked of the best table: the max bar, and 1 on every pixel."""
FEASIBLE = 1e-6
"""Largest :func:`smallest_violation` (table units) read as 0: HiGHS's tolerances are 1e-7."""
TIME_LIMIT_S = 300
"""HiGHS time limit per problem; a problem that hits it is reported as undecided."""


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
    table = torch.rand(3, size**3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    library = _KERNELS[interpolation](coords, table, size).numpy()
    mismatch = np.abs(matrix @ table.numpy().T - library.T).max()
    if mismatch > 1e-9:
        raise AssertionError(f"{interpolation} weights differ from the library's kernel by {mismatch}")
    return matrix


def entry_interval(codes: np.ndarray, t: float, encoding: str) -> tuple:
    """Table values whose displayed code is within ``t`` of ``codes``: ``(low, high)``, ±inf where the clip hides the error.

    Entries decode to linear (identity, or sRGB decoding) and display as ``255 srgb(clamp(., 0, 1))``.
    """
    def table_value(code):
        unit = torch.from_numpy(np.clip(code, 0.0, 255.0) / 255.0)
        return (unit if encoding == "srgb" else srgb_to_linear(unit)).numpy()

    low = np.where(codes - t <= 0.0, -np.inf, table_value(codes - t))
    high = np.where(codes + t >= 255.0, np.inf, table_value(codes + t))
    return low, high


def smallest_violation(matrix: csr_matrix, codes: np.ndarray, t: float, encoding: str):
    """How far, in table units, the best table column must leave some pixel's interval (:func:`entry_interval`).

    The elastic linear program ``min s`` subject to ``low - s <= A v <= high + s``, ``s >= 0``: always
    feasible, so HiGHS answers with a number instead of a verdict. 0 means a column keeping every pixel
    within ``t`` codes exists. Entries no pixel reads are fixed at 0. None if HiGHS stops without an optimum.
    """
    low, high = entry_interval(codes, t, encoding)
    bounded_above, bounded_below = np.isfinite(high), np.isfinite(low)
    rows = vstack([matrix[bounded_above], -matrix[bounded_below]])
    constraints = hstack([rows, csr_matrix(-np.ones((rows.shape[0], 1)))]).tocsr()
    limits = np.concatenate([high[bounded_above], -low[bounded_below]])
    used = np.zeros(matrix.shape[1], dtype=bool)
    used[matrix.indices] = True
    bounds = [(None, None) if u else (0.0, 0.0) for u in used] + [(0.0, None)]
    cost = np.zeros(matrix.shape[1] + 1)
    cost[-1] = 1.0
    result = linprog(cost, A_ub=constraints, b_ub=limits, bounds=bounds, method="highs", options={"time_limit": TIME_LIMIT_S})
    return float(result.fun) if result.status == 0 else None


def channel_violations(matrix: csr_matrix, codes: np.ndarray, t: float, encoding: str) -> list:
    """:func:`smallest_violation` of each channel of ``codes`` ``(3, P)`` (channels share no table entries)."""
    return [smallest_violation(matrix, channel, t, encoding) for channel in codes]


def table_exists(violations: list):
    """True when every channel's :func:`smallest_violation` is 0 (within HiGHS's tolerances), False when one is
    not, None when a channel is undecided and none is known to fail."""
    if any(v is not None and v > FEASIBLE for v in violations):
        return False
    return None if None in violations else True


def measured_pixels(image: torch.Tensor) -> tuple:
    """An image's pixels as the floor sees them: direct 8-bit codes ``(3, P)`` of the strong look, lattice
    coordinates ``(3, P)`` on the default LogC domain, and which pixels lie inside the lattice ``(P,)``."""
    with torch.no_grad():
        direct = srgb_codes(strong_look()(image.double())).reshape(3, -1).numpy()
    points = image.double().reshape(3, -1)
    low, high = DEFAULT_DOMAINS["logc"]
    coords = lattice_unit(points, "logc", low, high) * (SIZE - 1)
    inside = (points <= shaper_decode(torch.tensor(high, dtype=torch.float64), "logc")).all(dim=0).numpy()
    return direct, coords, inside


def floor_rows(name: str) -> list:
    """Every (interpolation, encoding, bar) answer for one image, and the baked LUT's own errors beside it."""
    look = strong_look()
    image = accuracy_image(name)
    direct, coords, inside = measured_pixels(image)
    luts = {encoding: bake_lut(look, size=SIZE, output_encoding=encoding) for encoding in OUTPUT_ENCODINGS}
    rows = []
    for interpolation in INTERPOLATIONS:
        matrix = interpolation_matrix(coords, SIZE, interpolation)
        for encoding, lut in luts.items():
            with torch.no_grad():
                baked = srgb_codes(lut(image, interpolation)).reshape(3, -1).numpy()
            error = np.abs(baked - direct)
            row = {"image": name, "outside_fraction": float(1.0 - inside.mean()), "interpolation": interpolation, "output_encoding": encoding,
                   "baked_p99_9": float(np.quantile(error, 0.999)), "baked_max": float(error.max())}
            problems = {f"max_{bar:g}": (matrix, direct, bar) for bar in BARS}
            problems[f"max_{MAX_BAR:g}_inside"] = (matrix[inside], direct[:, inside], MAX_BAR)  # without the clamped pixels
            for key, (pixels, codes, bar) in problems.items():
                start = time.perf_counter()
                violations = channel_violations(pixels, codes, bar, encoding)
                row[key] = {"table_exists": table_exists(violations), "violation": violations, "solve_s": time.perf_counter() - start}
            rows.append(row)
            print(row, flush=True)
    return rows


def markdown(report: dict) -> str:
    answer = {True: "yes", False: "**no**", None: "undecided"}
    bar, other = (f"{b:g}" for b in BARS)
    lines = [
        f"# Can any {SIZE}³ LogC table meet the accuracy bar? (linear programming, every 4th pixel)",
        "",
        "The look: contrast 30, saturation 20, temperature 20, ACES; default LogC domain (up to 58.86). "
        "Baked: the table `bake_lut` samples, its errors in 8-bit sRGB codes. Any table: does a table exist "
        "whose error is within the bar on every pixel (HiGHS, elastic linear program; 'no' means no choice of "
        "entries can, the smallest violation is in lut_floor.json). The last column leaves out the pixels with "
        "a channel above the lattice top, which the lookup clamps.",
        "",
        f"| image | pixels above the lattice | interpolation | output encoding | baked p99.9 | baked max | any table, max ≤ {bar} "
        f"| any table, max ≤ {other} | any table, max ≤ {bar} on the pixels inside the lattice |",
        "| --- | ---: | --- | --- | ---: | ---: | --- | --- | --- |",
    ]
    for r in report["rows"]:
        answers = " | ".join(answer[r[key]["table_exists"]] for key in (f"max_{bar}", f"max_{other}", f"max_{bar}_inside"))
        lines.append(
            f"| {r['image']} | {100 * r['outside_fraction']:.3f} % | {r['interpolation']} | {r['output_encoding']} | "
            f"{r['baked_p99_9']:.2f} | {r['baked_max']:.1f} | {answers} |"
        )
    lines += ["", f"Reproduce: `{report['command']}`", ""]
    return "\n".join(lines)


def main() -> None:
    import scipy

    rows = [row for name in ACCURACY_IMAGES for row in floor_rows(name)]
    report = {"command": COMMAND, "size": SIZE, "scipy": scipy.__version__, "torch": torch.__version__, "rows": rows}
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "lut_floor.json").write_text(json.dumps(report, indent=2) + "\n")
    (out / "lut_floor.md").write_text(markdown(report))
    print(markdown(report))


if __name__ == "__main__":
    main()
