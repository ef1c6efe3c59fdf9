"""The default lattice against the two it replaced, on photographs and on bright saturated colours.

Three lattices, each at its default size: ``"logc_extended"`` (the default of ``bake_lut``, ``look.to_lut()`` and, as
its ``.cube`` form, ``torchgrade bake``: the ``"logc"`` lattice to 58.86 and 12 more planes to 65504, 45³),
``"logc"`` (33³, clamps at 58.86: the former CLI default) and ``"logc_hdr"`` (33³, LogC to 58.86 on 27 intervals and
a tail on 5: the former Python default).

1. Photographs: two looks (the strong look of ``bench_lut.py`` and the shipped cinematic look's grade and tone
   mapper) baked with every default (linear entries, tetrahedral), applied to every 4th pixel of each photograph in
   ``../shared/data/exr``, against float64 direct evaluation, in 8-bit sRGB codes: p99.9, max and the share of
   values more than 1 code off.
2. Highlights: every tone mapper the bake takes, alone, baked with every default, on
   :func:`~torchgrade.lut.validation.bright_saturated_colours` (one channel from 58.86 to 65504, the others a fraction
   of it): the max error, which the bake's report holds to 2 codes where a lattice twice as fine would.

Run: ``.venv/bin/python -m benchmarks.lut_lattices [--out DIR]`` (writes lut_lattices.json and .md; the committed
ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import torch

import torchgrade as tg
from benchmarks.bench_lut import strong_look
from benchmarks.common import EXR_DIR, ROOT, argument_parser, write_results
from benchmarks.metrics import srgb_codes
from torchgrade.lut import LUTAccuracyWarning
from torchgrade.lut.report import HIGHLIGHT_TOLERANCE
from torchgrade.lut.validation import bright_saturated_colours
from torchgrade.tonemap import TONEMAP_MODES

COMMAND = ".venv/bin/python -m benchmarks.lut_lattices"
LATTICES = (("logc_extended", 45), ("logc", 33), ("logc_hdr", 33))
PHOTOGRAPHS = ("Desk", "CandleGlass", "GoldenGate", "Carrots", "Garden", "WideColorGamut")


def looks() -> dict:
    """The two looks, by name, as per-pixel transforms."""
    cinematic = json.loads((ROOT / "export" / "looks" / "cinematic.json").read_text())
    return {"strong": strong_look(), "cinematic": tg.PostFX.from_config(cinematic).per_pixel_stages()}


def bake(transform, shaper: str, size: int):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        return tg.bake_lut(transform, size=size, shaper=shaper, report_tolerance=float("inf"))


def photograph_rows() -> list:
    rows = []
    for look_name, look in looks().items():
        luts = {shaper: bake(look, shaper, size) for shaper, size in LATTICES}
        for name in PHOTOGRAPHS:
            image = tg.io.read_exr(EXR_DIR / f"{name}.exr")[:3, ::4, ::4].unsqueeze(0)
            with torch.no_grad():
                direct = srgb_codes(look(image.double()))
                for shaper, lut in luts.items():
                    error = (srgb_codes(lut(image)) - direct).abs().flatten().numpy()
                    rows.append({"look": look_name, "image": name, "shaper": shaper, "size": lut.size,
                                 "p99_9": float(np.quantile(error, 0.999)), "max": float(error.max()),
                                 "over_1_code": float((error > 1.0).mean())})
    return rows


def highlight_rows() -> list:
    colours = bright_saturated_colours().reshape(1, 3, 1, -1)
    rows = []
    for mode in TONEMAP_MODES:
        if mode == "none":
            continue
        tonemap = tg.ToneMap(mode)
        with torch.no_grad():
            direct = srgb_codes(tonemap(colours))
            for shaper, size in LATTICES:
                lut = bake(tonemap, shaper, size)
                rows.append({"tonemap": mode, "shaper": shaper, "max": float((srgb_codes(lut(colours.float())) - direct).abs().max())})
    return rows


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    report = {"command": COMMAND, "lattices": [list(lattice) for lattice in LATTICES], "highlight_tolerance": HIGHLIGHT_TOLERANCE,
              "photographs": photograph_rows(), "highlights": highlight_rows()}
    write_results(args.out, "lut_lattices", report, markdown(report).splitlines(), COMMAND)


def markdown(report: dict) -> str:
    shapers = [shaper for shaper, _ in report["lattices"]]
    sizes = {shaper: size for shaper, size in report["lattices"]}
    heads = " | ".join(f"{s} {sizes[s]}³ p99.9 / max / > 1 code" for s in shapers)
    lines = ["# The default LUT lattice against the two it replaced", "",
             "Every default (linear entries, tetrahedral); 8-bit sRGB codes against float64 direct evaluation, every 4th "
             "pixel of each photograph. `logc_extended` is the default of `bake_lut`, `look.to_lut()` and, as its "
             "`.cube` form (its planes up to 58.86, the `logc` 33³ lattice's), `torchgrade bake`.", "",
             f"| look | photograph | {heads} |", "| --- | --- |" + " ---: |" * len(shapers)]
    photographs = report["photographs"]
    for look in dict.fromkeys(r["look"] for r in photographs):
        for image in dict.fromkeys(r["image"] for r in photographs):
            cells = []
            for shaper in shapers:
                r = next(r for r in photographs if (r["look"], r["image"], r["shaper"]) == (look, image, shaper))
                cells.append(f"{r['p99_9']:.2f} / {r['max']:.1f} / {100 * r['over_1_code']:.1f} %")
            lines.append(f"| {look} | {image} | {' | '.join(cells)} |")
    lines += ["", f"## Bright saturated colours through each tone mapper alone (max codes; the report's tolerance "
              f"{report['highlight_tolerance']:g} where a lattice twice as fine holds them)", "", f"| tone mapper | {' | '.join(f'{s} {sizes[s]}³' for s in shapers)} |",
              "| --- |" + " ---: |" * len(shapers)]
    highlights = report["highlights"]
    for mode in dict.fromkeys(r["tonemap"] for r in highlights):
        cells = [f"{next(r['max'] for r in highlights if (r['tonemap'], r['shaper']) == (mode, s)):.1f}" for s in shapers]
        lines.append(f"| {mode} | {' | '.join(cells)} |")
    lines += ["", f"Reproduce: `{report['command']}`", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
