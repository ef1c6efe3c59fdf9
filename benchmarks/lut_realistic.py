"""Does a baked LUT's headline error (its report on realistic colours) predict its error on real frames?

Usage::

    .venv/bin/python -m benchmarks lut_realistic

For each look and lattice size, bakes the look's per-pixel stages as the commands do (``torchgrade bake``: ``logc``
for a look given by flags; ``look.to_lut`` and ``export --lut``: ``logc_extended``; tetrahedral, linear entries) and
compares the report's figure on realistic colours (`tg.lut.realistic_colours`) with the p99.9
error measured on the five natural sample images (CandleGlass, Carrots, Desk, Garden, GoldenGate), every
4th pixel of each (`STRIDE`) as the LUT receives it (after the look's exposure and bloom), in 8-bit sRGB codes
against the look evaluated directly in float64. *Pooled*: the p99.9 over 16,384 pixels (`PIXELS`) drawn from each
image (every image weighs the same). Ratio: report / pooled. The worst case (validation colours over the whole
domain) is shown beside it. Writes ``lut_realistic.{md,json}`` to ``--out`` (default benchmarks/out; the committed ones
with ``--out benchmarks/results``); about two minutes on 2 cores.

A second table is the shipped look as ``look.to_lut()`` bakes it (51³) on every sample image, every pixel: the
report's figure on the realistic colours and, with the image given as ``frames=``, on the image's own pixels,
each against the p99.9 the LUT really gets there.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import torch

import torchgrade as tg
from benchmarks.common import argument_parser, sample_exr, write_results
from benchmarks.suite.stamp import source_commit
from torchgrade.lut import LUTAccuracyWarning, code_errors

ROOT = Path(__file__).resolve().parents[1]

IMAGES = ("CandleGlass", "Carrots", "Desk", "Garden", "GoldenGate")
"""The natural sample images (the others are charts and ramps)."""

EVERY_IMAGE = IMAGES + ("WideColorGamut", "WideFloatRange", "BrightRings", "GrayRampsHorizontal", "AllHalfValues")
"""Every RGB sample image, charts and ramps too, for the ``frames=`` table."""

STRIDE = 4
"""Every STRIDE-th pixel of each image, in both directions."""

PIXELS = 16384
"""Pixels drawn (seeded) from each image's strided pixels for the pooled figure."""

SIZES = (17, 33, 65)

TOLERANCE = 1.0
"""``bake_lut``'s default ``report_tolerance``: 8-bit codes at p99.9."""

LOOKS = {
    "README bake: ACES grade, contrast 20, ACES": ({"grade": {"aces": True, "contrast": 20.0}, "tonemap": "aces"}, "logc"),
    "README Python: contrast 20, saturation 10, ACES": ({"grade": {"contrast": 20.0, "saturation": 10.0}, "tonemap": "aces"},
                                                         "logc_extended"),
    "cinematic (export/looks/cinematic.json)": (ROOT / "export" / "looks" / "cinematic.json", "logc_extended"),
    "strong: contrast 30, saturation 20, temperature 20, ACES": (
        {"grade": {"contrast": 30.0, "saturation": 20.0, "temperature": 20.0}, "tonemap": "aces"}, "logc_extended"),
    "strong, Reinhard": ({"grade": {"contrast": 30.0, "saturation": 20.0, "temperature": 20.0}, "tonemap": "reinhard"},
                         "logc_extended"),
}
"""Each look's config and the shaper its command bakes."""


def quantile_999(errors: torch.Tensor) -> float:
    """The 99.9th percentile of ``errors`` (the higher value, as the report takes it)."""
    flat = errors.flatten()
    return float(flat.kthvalue(max(1, -(-999 * flat.numel() // 1000))).values)


def received_pixels(look: tg.PostFX) -> dict:
    """Each image's strided pixels as the look's per-pixel stages receive them, ``{name: (1, 3, 1, N) float32}``."""
    pixels = {}
    with torch.no_grad():
        for name in IMAGES:
            image = look.per_pixel_input(sample_exr(name)[..., ::STRIDE, ::STRIDE])
            pixels[name] = image.reshape(1, 3, 1, -1)
    return pixels


def measured(look: tg.PostFX, shaper: str, size: int, pixels: dict) -> dict:
    """The report's figures and the measured p99.9 on each image and pooled, for one bake."""
    transform = look.per_pixel_stages()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        lut = tg.bake_lut(transform, size=size, shaper=shaper, report_tolerance=float("inf"))
    errors = {}
    with torch.no_grad():
        for name, image in pixels.items():
            errors[name] = code_errors(transform(image.double()), lut(image, "tetrahedral"))
    generator = torch.Generator().manual_seed(0)
    pooled = torch.cat([e[..., torch.randint(0, e.shape[-1], (PIXELS,), generator=generator)] for e in errors.values()], -1)
    report = lut.error_report
    return {"realistic": report.p99_9, "worst_p99_9": report.worst_case.p99_9, "worst_max": report.worst_case.max,
            "pooled": quantile_999(pooled), "images": {name: quantile_999(e) for name, e in errors.items()}}


def framed_rows(look: tg.PostFX) -> list:
    """For each of :data:`EVERY_IMAGE`: ``look.to_lut()``'s report on realistic colours, ``look.to_lut(frames=image)``'s
    report, and the p99.9 each LUT really gets on every pixel of the image."""
    transform = look.per_pixel_stages()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        default = look.to_lut().lut
        rows = []
        for name in EVERY_IMAGE:
            image = sample_exr(name)
            framed = look.to_lut(frames=image).lut
            with torch.no_grad():
                received = look.per_pixel_input(image)
                direct = transform(received.double())
                real = {key: quantile_999(code_errors(direct, lut(received))) for key, lut in (("default", default), ("framed", framed))}
            rows.append({"image": name, "size": list(image.shape[-2:]), "realistic_report": default.error_report.p99_9,
                         "realistic_real": real["default"], "frames_report": framed.error_report.p99_9, "frames_real": real["framed"]})
    return rows


def framed_lines(rows: list) -> list:
    """The ``frames=`` table and its summary line."""
    lines = ["", "## The shipped look's `to_lut()` (51³, logc_extended), reported on realistic colours or on the image as `frames=`", "",
             "| image | pixels | report: realistic p99.9 | real p99.9 | real / report | report: `frames=` p99.9 | real p99.9 | real / report |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for row in rows:
        lines.append(f"| {row['image']} | {row['size'][1]}×{row['size'][0]} | {row['realistic_report']:.2f} | {row['realistic_real']:.2f} | "
                     f"{row['realistic_real'] / row['realistic_report']:.2f} | {row['frames_report']:.2f} | {row['frames_real']:.2f} | "
                     f"{row['frames_real'] / row['frames_report']:.2f} |")
    default = [row["realistic_real"] / row["realistic_report"] for row in rows]
    framed = [row["frames_real"] / row["frames_report"] for row in rows]
    lines += ["", f"Real / report: {min(default):.2f} to {max(default):.2f} on realistic colours, {min(framed):.2f} to "
              f"{max(framed):.2f} with `frames=` (every pixel of the image)."]
    return lines


def main(argv=None) -> None:
    out = argument_parser(__doc__).parse_args(argv).out
    torch.manual_seed(0)
    command, stamp = f".venv/bin/python -m benchmarks lut_realistic --out {out}", source_commit()
    rows, lines = [], ["# A baked LUT's report on realistic colours against its error on the sample images", "",
                       f"Made by `{command}` at commit `{stamp['commit'][:7]}`{' with uncommitted changes' if stamp['modified'] else ''}.", "",
                       __doc__.split("\n\n")[3].replace("\n", " ").replace("``", "`"), "",
                       "| look | size | shaper | report: realistic p99.9 | pooled images p99.9 | ratio | images p99.9 "
                       f"({' / '.join(IMAGES)}) | worst case p99.9 / max |",
                       "| --- | ---: | --- | ---: | ---: | ---: | --- | ---: |"]
    for label, (config, shaper) in LOOKS.items():
        look = tg.PostFX.from_config(config).eval()
        pixels = received_pixels(look)
        for size in SIZES:
            row = {"look": label, "size": size, "shaper": shaper, **measured(look, shaper, size, pixels)}
            rows.append(row)
            per_image = " / ".join(f"{row['images'][name]:.2f}" for name in IMAGES)
            lines.append(f"| {label} | {size}³ | {shaper} | {row['realistic']:.2f} | {row['pooled']:.2f} | "
                         f"{row['realistic'] / row['pooled']:.2f} | {per_image} | {row['worst_p99_9']:.2f} / {row['worst_max']:.1f} |")
    ratios = [row["realistic"] / row["pooled"] for row in rows]
    agree = sum((row["realistic"] <= TOLERANCE) == (row["pooled"] <= TOLERANCE) for row in rows)
    lines += ["", f"Ratio report / pooled: {min(ratios):.2f} to {max(ratios):.2f} over {len(rows)} bakes; "
              f"single images' p99.9 range from {min(min(r['images'].values()) / r['realistic'] for r in rows):.2f}x "
              f"to {max(max(r['images'].values()) / r['realistic'] for r in rows):.2f}x the report's figure. "
              f"The verdict (p99.9 within {TOLERANCE:g} code) agrees with the pooled images' in {agree} of {len(rows)}."]
    framed = framed_rows(tg.PostFX.from_config(LOOKS["cinematic (export/looks/cinematic.json)"][0]).eval())
    lines += framed_lines(framed)
    write_results(out, "lut_realistic", {"command": command, **stamp, "rows": rows, "frames": framed}, lines, command)


if __name__ == "__main__":
    main()
