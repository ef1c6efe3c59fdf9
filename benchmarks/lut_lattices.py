"""The default lattice against the two it replaced, on photographs and on bright saturated colours.

Three lattices, each at its default size: ``"logc_extended"`` (the default of ``bake_lut``, ``look.to_lut()`` and, as
its ``.cube`` form, ``torchgrade bake``: the ``"logc"`` 39³ lattice to 58.86 and 12 more planes to 65504, 51³),
``"logc"`` (33³, clamps at 58.86: the former CLI default) and ``"logc_hdr"`` (33³, LogC to 58.86 on 27 intervals and
a tail on 5: the former Python default).

1. Photographs: two looks (the strong look of ``bench_lut.py`` and the shipped cinematic look's grade and tone
   mapper) baked with every default (tetrahedral; linear entries, the default, and sRGB entries), applied to every 4th pixel of each photograph in
   ``../shared/data/exr``, against float64 direct evaluation, in 8-bit sRGB codes: p99.9, max and the share of
   values more than 1 code off; and the same on the pixels inside every lattice's domain (no channel below 0, where
   each lattice starts), for the photographs with pixels outside it.
2. Highlights: every tone mapper the bake takes, alone, baked with every default, on
   :func:`~torchgrade.lut.validation.bright_saturated_colours` (one channel from 58.86 to 65504, the others a fraction
   of it): the max error, which the bake's report holds to 2 codes where a lattice twice as fine would.

Run: ``.venv/bin/python -m benchmarks lut_lattices [--out DIR]`` (writes lut_lattices.json and .md; the committed
ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import itertools
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

COMMAND = ".venv/bin/python -m benchmarks lut_lattices"
LATTICES = (("logc_extended", 51), ("logc", 33), ("logc_hdr", 33))
ENCODINGS = ("linear", "srgb")
"""The table's entries: linear (the bake's default) or sRGB-encoded (``output_encoding="srgb"``)."""
PHOTOGRAPHS = ("Desk", "CandleGlass", "GoldenGate", "Carrots", "Garden", "WideColorGamut")


def looks() -> dict:
    """The two looks, by name, as per-pixel transforms."""
    cinematic = json.loads((ROOT / "export" / "looks" / "cinematic.json").read_text())
    return {"strong": strong_look(), "cinematic": tg.PostFX.from_config(cinematic).per_pixel_stages()}


def bake(transform, shaper: str, size: int, output_encoding: str = "linear"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        return tg.bake_lut(transform, size=size, shaper=shaper, output_encoding=output_encoding, report_tolerance=float("inf"))


QUICK = "every 16th pixel of each photograph instead of every 4th"
"""What ``--quick`` leaves out."""


def photograph_rows(stride: int = 4) -> list:
    rows = []
    for (look_name, look), encoding in itertools.product(looks().items(), ENCODINGS):
        luts = {shaper: bake(look, shaper, size, encoding) for shaper, size in LATTICES}
        for name in PHOTOGRAPHS:
            image = tg.io.read_exr(EXR_DIR / f"{name}.exr")[:3, ::stride, ::stride].unsqueeze(0)
            inside = (image >= 0).all(dim=1, keepdim=True).expand_as(image).flatten().numpy()
            with torch.no_grad():
                direct = srgb_codes(look(image.double()))
                for shaper, lut in luts.items():
                    error = (srgb_codes(lut(image)) - direct).abs().flatten().numpy()
                    rows.append({"look": look_name, "entries": encoding, "image": name, "shaper": shaper, "size": lut.size,
                                 **error_figures(error), "below_black": float(1.0 - inside.mean()),
                                 "inside": error_figures(error[inside])})
    return rows


def error_figures(error: np.ndarray) -> dict:
    """p99.9, max and the share of values more than 1 code off."""
    return {"p99_9": float(np.quantile(error, 0.999)), "max": float(error.max()), "over_1_code": float((error > 1.0).mean())}


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
    args = argument_parser(__doc__, QUICK).parse_args(argv)
    stride = 16 if args.quick else 4
    report = {"command": COMMAND + (" --quick" if args.quick else ""), "lattices": [list(lattice) for lattice in LATTICES],
              "highlight_tolerance": HIGHLIGHT_TOLERANCE, "stride": stride, "photographs": photograph_rows(stride),
              "highlights": highlight_rows()}
    write_results(args.out, "lut_lattices", report, markdown(report).splitlines(), report["command"])


def markdown(report: dict) -> str:
    shapers = [shaper for shaper, _ in report["lattices"]]
    sizes = {shaper: size for shaper, size in report["lattices"]}
    heads = " | ".join(f"{s} {sizes[s]}³ p99.9 / max / > 1 code" for s in shapers)
    photographs = report["photographs"]
    cases = list(dict.fromkeys((r["look"], r["entries"], r["image"]) for r in photographs))

    def cells(case: tuple, part=lambda r: r) -> str:
        found = {r["shaper"]: part(r) for r in photographs if (r["look"], r["entries"], r["image"]) == case}
        return " | ".join(f"{found[s]['p99_9']:.2f} / {found[s]['max']:.1f} / {100 * found[s]['over_1_code']:.1f} %" for s in shapers)

    lines = ["# The default LUT lattice against the two it replaced", "",
             "Every default (tetrahedral; linear entries, the default, and sRGB entries); 8-bit sRGB codes against float64 "
             f"direct evaluation, every {report['stride']}th pixel of each photograph. `logc_extended` is the default of `bake_lut`, "
             "`look.to_lut()` and, as its `.cube` form (its planes up to 58.86, the `logc` 39³ lattice's), `torchgrade bake`.", "",
             f"| look | entries | photograph | {heads} |", "| --- | --- | --- |" + " ---: |" * len(shapers)]
    lines += [f"| {' | '.join(case)} | {cells(case)} |" for case in cases]
    outside = [case for case in cases if next(r for r in photographs if (r["look"], r["entries"], r["image"]) == case)["below_black"] > 0]
    if outside:
        lines += ["", "## The same on the pixels inside every lattice (no channel below 0: each lattice starts at black and clamps "
                  "below it)", "", f"| look | entries | photograph | pixels with a channel below 0 | {heads} |",
                  "| --- | --- | --- | ---: |" + " ---: |" * len(shapers)]
        for case in outside:
            below = next(r for r in photographs if (r["look"], r["entries"], r["image"]) == case)["below_black"]
            lines.append(f"| {' | '.join(case)} | {100 * below:.1f} % | {cells(case, lambda r: r['inside'])} |")
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
