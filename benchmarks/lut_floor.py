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
from scipy.sparse import csr_matrix, vstack

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_lut import ACCURACY_IMAGES, SIZE, accuracy_image, strong_look  # noqa: E402
from benchmarks.metrics import srgb_codes  # noqa: E402
from torchgrade.color import srgb_to_linear  # noqa: E402
from torchgrade.lut import DEFAULT_DOMAINS, INTERPOLATIONS, OUTPUT_ENCODINGS, _KERNELS, bake_lut, lattice_unit, shaper_decode  # noqa: E402

COMMAND = ".venv/bin/python benchmarks/lut_floor.py"
BARS = (4.0, 1.0)
"""Max errors (8-bit codes) asked of the best table: the max bar, and 1 on every pixel."""
TIME_LIMIT_S = 120
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


def table_exists(matrix: csr_matrix, codes: np.ndarray, t: float, encoding: str):
    """Whether some table has every pixel within ``t`` codes: True, False, or None (undecided), channels ``(3, P)`` in turn."""
    answers = []
    for channel_codes in codes:
        answers.append(column_exists(matrix, channel_codes, t, encoding))
        if answers[-1] is False:
            return False
    return None if None in answers else True


def column_exists(matrix: csr_matrix, codes: np.ndarray, t: float, encoding: str):
    """Whether some table column ``v`` has ``low <= A v <= high`` for every pixel: True, False, or None (undecided)."""
    low, high = entry_interval(codes, t, encoding)
    bounded_above, bounded_below = np.isfinite(high), np.isfinite(low)
    constraints = vstack([matrix[bounded_above], -matrix[bounded_below]]).tocsr()
    limits = np.concatenate([high[bounded_above], -low[bounded_below]])
    used = np.zeros(matrix.shape[1], dtype=bool)
    used[matrix.indices] = True  # entries no pixel reads are fixed at 0
    bounds = [(None, None) if u else (0.0, 0.0) for u in used]
    result = linprog(np.zeros(matrix.shape[1]), A_ub=constraints, b_ub=limits, bounds=bounds, method="highs",
                     options={"time_limit": TIME_LIMIT_S})
    return {0: True, 2: False}.get(result.status)


def measured_pixels(name: str) -> tuple:
    """An image's pixels as the floor sees them: direct 8-bit codes ``(3, P)`` of the strong look, lattice
    coordinates ``(3, P)`` on the default LogC domain, and which pixels lie inside the lattice ``(P,)``."""
    image = accuracy_image(name)
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
    direct, coords, inside = measured_pixels(name)
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
            for bar in BARS:
                start = time.perf_counter()
                row[f"table_with_max_{bar:g}"] = table_exists(matrix, direct, bar, encoding)
                row[f"solve_s_{bar:g}"] = time.perf_counter() - start
            # Without the pixels the lattice clamps (a subset: a table for all pixels serves it too).
            row["table_with_max_4_inside"] = row["table_with_max_4"] or table_exists(matrix[inside], direct[:, inside], 4.0, encoding)
            rows.append(row)
            print(row, flush=True)
    return rows


def markdown(report: dict) -> str:
    answer = {True: "yes", False: "**no**", None: "undecided"}
    lines = [
        f"# Can any {SIZE}³ LogC table meet the accuracy bar? (linear programming, every 4th pixel)",
        "",
        "The look: contrast 30, saturation 20, temperature 20, ACES; default LogC domain (up to 58.86). "
        "Baked: the table `bake_lut` samples, its errors in 8-bit sRGB codes. Any table: does a table exist "
        "whose error is within the bar on every pixel (HiGHS; 'no' is a proof that no choice of entries can); "
        "the last column leaves out the pixels with a channel above the lattice top, which the lookup clamps.",
        "",
        "| image | pixels above the lattice | interpolation | output encoding | baked p99.9 | baked max | any table, max ≤ 4 | any table, max ≤ 1 | any table, max ≤ 4 on the pixels inside the lattice |",
        "| --- | ---: | --- | --- | ---: | ---: | --- | --- | --- |",
    ]
    for r in report["rows"]:
        lines.append(
            f"| {r['image']} | {100 * r['outside_fraction']:.3f} % | {r['interpolation']} | {r['output_encoding']} | {r['baked_p99_9']:.2f} | "
            f"{r['baked_max']:.1f} | {answer[r['table_with_max_4']]} | {answer[r['table_with_max_1']]} | {answer[r['table_with_max_4_inside']]} |"
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
