"""What fitted LUT entries (``bake_lut(entries="fitted")``) buy on real images, on the pixels fitted and on their
unseen neighbours, against the floor of any 33³ LogC table and of any table on the fitted lattice.

Strong look (contrast 30, saturation 20, temperature 20, ACES; graded in Rec.709), 33³, sRGB-encoded entries,
tetrahedral lookup; errors in 8-bit sRGB codes against float64 direct evaluation. *Seen*: every 4th pixel from
offset 0 (the pixels ``benchmarks/lut_floor.py`` bounds; scene bakes get them as ``scene=``). *Unseen*: every 4th
pixel from offset 2, which no fit saw. *Report*: the bake's own error report (validation colours of another seed
than the fit's, plus the scene for scene bakes). *Floor*: bounds on the smallest max error any table on that
lattice reaches on the seen pixels (HiGHS, :func:`benchmarks.lut_floor.lowest_max_error`; the LogC floors are
read from ``results/lut_floor.json``, the lowest over its lattices and both interpolations).

Run: ``.venv/bin/python -m benchmarks lut_fit [--out DIR]`` (about 15 minutes on two cores; writes
lut_fit.json and lut_fit.md to ``--out``, default benchmarks/out; the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from benchmarks.common import RESULTS, argument_parser, write_results
from benchmarks.bench_lut import ACCURACY_IMAGES, SIZE, sample_exr, strong_look
from benchmarks.lut_floor import interpolation_matrix, lowest_max_error
from benchmarks.metrics import srgb_codes
from torchgrade.lut.fit import SCENE_FIT_WEIGHT
from torchgrade.lut.entries import SCENE_WEIGHT
from torchgrade.lut import bake_lut, fit_entries
from torchgrade.lut.shapers import lattice_unit

ROOT = Path(__file__).resolve().parents[1]

COMMAND = ".venv/bin/python -m benchmarks lut_fit"
LATTICES = {"LogC to 65504 (default)": {"shaper": "logc_hdr"}, "LogC to 58.86": {"shaper": "logc"}, "fitted to the look": {"shaper": "fitted"},
            "fitted to the scene": {"shaper": "fitted", "scene": True}}
"""``bake_lut`` arguments of each lattice (``scene: True`` passes the seen pixels)."""
LOGC_TOP = 58.86
"""The linear top of the LogC lattice: a seen pixel with a channel above it is clamped there by a LogC table
(``seen_above_logc_top``: how many, and the largest error on them)."""
SCENE_WEIGHTS = (SCENE_WEIGHT, 64.0, SCENE_FIT_WEIGHT, 1e6)
"""Scene-pixel weights swept on the scene-fitted lattice (1e6: the scene alone, as the floor counts it)."""


def errors(lut, pixels: torch.Tensor, direct: np.ndarray) -> np.ndarray:
    """8-bit code errors ``(3, P)`` of ``lut`` (tetrahedral) on ``pixels`` against ``direct`` codes."""
    with torch.no_grad():
        return np.abs(srgb_codes(lut(pixels)).reshape(3, -1).numpy() - direct)


def summary(error: np.ndarray) -> dict:
    return {"p99_9": float(np.quantile(error, 0.999)), "max": float(error.max())}


def logc_floor(image: str) -> float:
    """The lowest lower bound on any 33³ LogC table's max error on ``image`` (Rec.709 look), from lut_floor.json."""
    rows = json.loads((RESULTS / "lut_floor.json").read_text())["rows"]
    return min(row["lowest_max"][0] for row in rows if row["image"] == image and row["look"] == "Rec.709" and row["lowest_max"])


def lattice_floor(lut, seen: torch.Tensor, direct: np.ndarray) -> list:
    """Bounds on the smallest max error of any table on ``lut``'s lattice (tetrahedral) on the ``seen`` pixels."""
    points = seen.double().reshape(3, -1)
    curve = None if lut.curve is None else lut.curve.double()
    unit = lattice_unit(points, lut.shaper, lut.domain_min.double(), lut.domain_max.double(), curve, lut.curve_range)
    return list(lowest_max_error(interpolation_matrix(unit * (SIZE - 1), SIZE, "tetrahedral"), direct))


def image_rows(name: str) -> list:
    """Every row of one image: each lattice sampled and fitted, then the scene-weight sweep."""
    look = strong_look()
    image = sample_exr(name)
    seen, unseen = image[..., ::4, ::4], image[..., 2::4, 2::4]
    with torch.no_grad():
        direct = {part: srgb_codes(look(pixels.double())).reshape(3, -1).numpy() for part, pixels in (("seen", seen), ("unseen", unseen))}
    rows = []

    above = (seen.amax(1, keepdim=True) > LOGC_TOP).expand_as(seen).reshape(3, -1).numpy()

    def row(lattice: str, entries: str, lut, seconds: float, **extra) -> dict:
        result = {"image": name, "lattice": lattice, "entries": entries, "seconds": seconds, **extra,
                  "report": {"p99_9": lut.error_report.p99_9, "max": lut.error_report.max} if lut.error_report else None}
        measured = {part: errors(lut, pixels, direct[part]) for part, pixels in (("seen", seen), ("unseen", unseen))}
        result.update({part: summary(error) for part, error in measured.items()})
        result["seen_above_logc_top"] = {"pixels": int(above[0].sum()),
                                         "max": float(measured["seen"][above].max()) if above.any() else None}
        return result

    for lattice, arguments in LATTICES.items():
        arguments = {**arguments, "scene": seen if arguments.get("scene") else None}
        luts = {}
        for entries in ("sampled", "fitted"):
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                luts[entries] = bake_lut(look, size=SIZE, output_encoding="srgb", entries=entries, **arguments)
            rows.append(row(lattice, entries, luts[entries], time.perf_counter() - start))
        if arguments["scene"] is not None:
            floor = lattice_floor(luts["fitted"], seen, direct["seen"])
            rows[-1]["floor"] = floor
            sampled = luts["sampled"]  # the same lattice: the scene fit is deterministic
            for weight in SCENE_WEIGHTS:
                start = time.perf_counter()
                fitted = fit_entries(sampled, look, seen, scene_weight=weight)
                fitted.error_report = None
                rows.append(row(lattice, f"fitted, scene weight {weight:g}", fitted, time.perf_counter() - start, floor=floor))
    return rows


def markdown(report: dict) -> str:
    lines = [
        "# Fitted LUT entries: 33³, strong look (Rec.709 grade, ACES), sRGB entries, tetrahedral",
        "",
        f"`{COMMAND}` (torch {report['torch']}). Errors in 8-bit sRGB codes against float64 direct evaluation. Seen: every 4th "
        "pixel from offset 0 (what scene bakes fit, and what benchmarks/lut_floor.py bounds); unseen: every 4th pixel from offset 2. "
        "Report: the bake's error report (validation colours of another seed than the fit's, plus the scene). Floor of this lattice: "
        "bounds on the smallest max error of any table on it, seen pixels (HiGHS). LogC floor: the lowest lower bound on any 33³ "
        "LogC table's max error on the seen pixels over every lattice and interpolation of results/lut_floor.md. Default weights: a "
        f"scene pixel {SCENE_WEIGHT:g} ({SCENE_FIT_WEIGHT:g} on the scene-fitted lattice), a validation colour 1, a lattice point (held "
        "to its sampled value) 1. The lattice fitted to the scene (torchgrade/lut/fit.py, fit_scene_shaper): per channel, planes "
        "evenly in log2(x + 0.03) from black to 4x the scene's 99.9th percentile, an interval on to its largest value, one on to "
        "65504, moved by the errors of tables with fitted entries over six bake-and-fit rounds (a half step after a round that did "
        "not improve); the scene-weight rows refit its sampled table.",
        "",
        "| image | lattice | entries | seen p99.9 | seen max | unseen p99.9 | unseen max | report p99.9 | report max | floor of this lattice | LogC floor | s |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in report["rows"]:
        floor = "–".join(f"{v:.2f}" for v in row["floor"]) if row.get("floor") else ""
        rep = row["report"]
        lines.append(f"| {row['image']} | {row['lattice']} | {row['entries']} | {row['seen']['p99_9']:.2f} | {row['seen']['max']:.2f} | "
                     f"{row['unseen']['p99_9']:.2f} | {row['unseen']['max']:.2f} | {rep['p99_9']:.2f} | {rep['max']:.1f} | "
                     if rep else
                     f"| {row['image']} | {row['lattice']} | {row['entries']} | {row['seen']['p99_9']:.2f} | {row['seen']['max']:.2f} | "
                     f"{row['unseen']['p99_9']:.2f} | {row['unseen']['max']:.2f} | | | ")
        lines[-1] += f"{floor} | {report['logc_floor'][row['image']]:.2f} | {row['seconds']:.1f} |"
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    torch.manual_seed(0)
    rows = [row for name in ACCURACY_IMAGES for row in image_rows(name)]
    report = {"command": COMMAND, "torch": torch.__version__, "size": SIZE,
              "logc_floor": {name: logc_floor(name) for name in ACCURACY_IMAGES}, "rows": rows}
    write_results(args.out, "lut_fit", report, markdown(report).splitlines(), COMMAND)


if __name__ == "__main__":
    main()
