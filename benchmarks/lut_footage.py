"""Can a colourist plan on a baked LUT's report? Its figures against what the LUT really gets, every pixel counted.

Usage::

    .venv/bin/python -m benchmarks lut_footage

For each look, bakes its per-pixel stages as ``bake_lut`` does by default (``logc_extended`` at its default size,
tetrahedral, linear entries; the results name the lattice) and sets the report's three figures (p99.9, 8-bit sRGB codes against the look in float64) beside the
p99.9 the LUT gets on every pixel of pictures of that footage: the realistic colours' beside each natural sample
photograph (as the LUT receives it, after the look's exposure and bloom), the colour charts' beside two charts, the
warm practicals' beside three candle-lit still lifes. The pictures are built from colour-science's reference data,
which the library never reads (:func:`chart_picture`, :func:`still_life`). Ratio: report / real; the tests hold it
within 2x (``tests/lut/test_lut_footage.py``). A second table is the shipped look's ``to_lut(frames=image)`` on
every sample image: the report's p99.9 and max, and the real ones over every pixel. Writes ``lut_footage.{md,json}``
to ``--out`` (default benchmarks/out; the committed ones with ``--out benchmarks/results``), stamped with the commit
it measured; minutes on 2 cores.

Accuracy only, so a busy machine may make the committed ones. The summary and ``frames=`` tables are marked
(:func:`~benchmarks.common.mark_table`) so that ``python -m benchmarks suite --pages`` copies them onto docs/lut.md.
"""

from __future__ import annotations

import warnings

import colour
import numpy as np
import torch
from colour.quality.datasets import SDS_TCS, SDS_VS

import torchgrade as tg
from benchmarks.common import ROOT, argument_parser, mark_table, sample_exr, write_results
from benchmarks.suite.stamp import source_commit
from torchgrade.lut import LUTAccuracyWarning, code_errors

COMMAND = ".venv/bin/python -m benchmarks lut_footage"
MARGIN = 2.0
"""The factor, either way, within which a report's figure should be of the real p99.9 on pictures of its footage."""

REC709 = colour.RGB_COLOURSPACES["ITU-R BT.709"]
SPECTRUM = colour.SpectralShape(380, 780, 5)
OBSERVER = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(SPECTRUM)

CHART_EXPOSURES = np.arange(-4.0, 4.0 + 1e-9, 1.0 / 3.0) + 1.0 / 64.0
"""A chart shot at 25 exposures within the 4 stops either side of its published values, off the report's 1/32-stop grid."""

CHARTS = ("ColorCheckerSG - After November 2014", "ColorChecker 2005")
"""The charts (colour-science's CIE xyY): the SG's 140 patches, and the Classic's 24 as measured in 2005."""

STILL_LIFE_KELVIN = (1850.0, 2250.0, 2650.0)
"""The flames' colour temperatures: a candle, a warmer and a cooler practical."""

PHOTOGRAPHS = ("CandleGlass", "Carrots", "Desk", "Garden", "GoldenGate")
"""The natural sample photographs."""

EVERY_IMAGE = PHOTOGRAPHS + ("WideColorGamut", "WideFloatRange", "BrightRings", "GrayRampsHorizontal", "AllHalfValues")
"""Every RGB sample image, charts and ramps too, for the ``frames=`` table."""

FIGURES = {"realistic colours": "photographs", "colour charts": "charts", "warm practicals": "still lifes"}
"""The report's figures, each by the pictures of its footage it is set against."""

LOOKS = {
    "cinematic (export/looks/cinematic.json)": ROOT / "export" / "looks" / "cinematic.json",
    "README Python: contrast 20, saturation 10, ACES": {"grade": {"contrast": 20.0, "saturation": 10.0}, "tonemap": "aces"},
    "strong: contrast 30, saturation 20, temperature 20, ACES": {
        "grade": {"contrast": 30.0, "saturation": 20.0, "temperature": 20.0}, "tonemap": "aces"},
    "contrast -10, saturation 30, temperature -20, tint 10, AgX": {
        "grade": {"contrast": -10.0, "saturation": 30.0, "temperature": -20.0, "tint": 10.0}, "tonemap": "agx"},
    "contrast 15, saturation 10, Neutral": {"grade": {"contrast": 15.0, "saturation": 10.0}, "tonemap": "neutral"},
}


def chart_picture(name: str, patch: int = 4) -> torch.Tensor:
    """``name``'s patches (colour-science's CIE xyY) in linear Rec.709, Bradford-adapted from the chart's white to D65,
    ``patch`` pixels square, one row of patches an exposure of :data:`CHART_EXPOSURES`; ``(1, 3, H, W)`` float64."""
    chart = colour.CCS_COLOURCHECKERS[name]
    rgb = colour.XYZ_to_RGB(colour.xyY_to_XYZ(np.array(list(chart.data.values()))), REC709,
                            illuminant=chart.illuminant, chromatic_adaptation_transform="Bradford")
    rows = rgb[None] * np.exp2(CHART_EXPOSURES)[:, None, None]
    image = np.repeat(np.repeat(rows, patch, axis=0), patch, axis=1)
    return torch.from_numpy(image.transpose(2, 0, 1)).unsqueeze(0)


def emitted_rec709(spectrum) -> np.ndarray:
    """An emitter's linear Rec.709, luminance 1, as a camera balanced for D65 records it (no adaptation)."""
    xyz = colour.sd_to_XYZ(spectrum.copy().align(SPECTRUM), OBSERVER, method="Integration")
    return colour.XYZ_to_RGB(xyz / xyz[1], REC709, illuminant=REC709.whitepoint, chromatic_adaptation_transform=None)


def lit_rec709(reflectances: list, light) -> np.ndarray:
    """Reflectances lit by ``light`` (the spectral product), linear Rec.709 with a perfect white at luminance 1."""
    light = light.copy().align(SPECTRUM)
    white = colour.sd_to_XYZ(colour.sd_ones(SPECTRUM), OBSERVER, light, method="Integration")[1]
    xyz = np.array([colour.sd_to_XYZ(r.copy().align(SPECTRUM), OBSERVER, light, method="Integration") for r in reflectances])
    return colour.XYZ_to_RGB(xyz / white, REC709, illuminant=REC709.whitepoint, chromatic_adaptation_transform=None)


def still_life(kelvin: float, size: int = 240, flame: float = 1000.0) -> torch.Tensor:
    """A candle-lit still life, ``(1, 3, size, size)`` float64. Top half: a flame (a black body at ``kelvin``, luminance
    ``flame`` at its core) and its glow, ``flame / (1 + r²)`` with ``r`` in units of the flame's size, over a wall of
    a grey sample lit by it. Bottom half: the 15 NIST CQS 9.0 and 14 CIE 13.3 test samples in rows, lit by the flame
    from 0.25 m (left) to 2 m (right), irradiance as ``1 / d²``, a white at 0.3 m at luminance 1."""
    light = colour.sd_blackbody(kelvin, SPECTRUM)
    samples = list(SDS_VS["NIST CQS 9.0"].values()) + list(SDS_TCS["CIE 1995"].values())
    lit = lit_rec709(samples, light)
    y, x = np.mgrid[0:size, 0:size] / size
    irradiance = ((0.3 / (0.25 + 1.75 * x)) ** 2)[..., None]
    glow = (flame / (1.0 + ((x - 0.5) ** 2 + ((y - 0.25) / 2.0) ** 2) / 0.02 ** 2))[..., None] * emitted_rec709(light)
    wall = glow + 0.2 * lit[-1] * irradiance
    rows = np.clip(((y - 0.5) * 2 * len(samples)).astype(int), 0, len(samples) - 1)
    image = np.where((y >= 0.5)[..., None], lit[rows] * irradiance, wall)
    return torch.from_numpy(image.transpose(2, 0, 1)).unsqueeze(0)


def real_errors(lut, transform, pixels: torch.Tensor) -> torch.Tensor:
    """8-bit sRGB code errors of ``lut`` against ``transform`` in float64 on every channel value of ``pixels``."""
    with torch.no_grad():
        return code_errors(transform(pixels.double()), lut(pixels.float()))


def quantile_999(errors: torch.Tensor) -> float:
    """The 99.9th percentile of ``errors`` (the higher value, as the report takes it)."""
    flat = errors.flatten()
    return float(flat.kthvalue(max(1, -(-999 * flat.numel() // 1000))).values)


def footage_rows(look: tg.PostFX) -> tuple:
    """``(lut, rows)``: one look's default bake, and each row's ``figure``, ``picture``, ``report`` (the stated p99.9)
    and ``real`` p99.9."""
    transform = look.per_pixel_stages()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        lut = tg.bake_lut(transform)
    report = lut.error_report
    stated = {"realistic colours": report.p99_9, **{kind.colour_set: kind.p99_9 for kind in report.footage}}
    rows = []
    for name in PHOTOGRAPHS:
        with torch.no_grad():
            received = look.per_pixel_input(sample_exr(name))
        rows.append(("realistic colours", name, stated["realistic colours"], quantile_999(real_errors(lut, transform, received))))
    for name in CHARTS:
        rows.append(("colour charts", name, stated["colour charts"], quantile_999(real_errors(lut, transform, chart_picture(name)))))
    for kelvin in STILL_LIFE_KELVIN:
        real = quantile_999(real_errors(lut, transform, still_life(kelvin)))
        rows.append(("warm practicals", f"still life, {kelvin:.0f} K", stated["warm practicals"], real))
    return lut, [dict(zip(("figure", "picture", "report", "real"), row)) for row in rows]


def framed_rows(look: tg.PostFX) -> list:
    """For each of :data:`EVERY_IMAGE`: ``look.to_lut(frames=image)``'s report and the real p99.9 and max, every pixel."""
    transform = look.per_pixel_stages()
    rows = []
    for name in EVERY_IMAGE:
        image = sample_exr(name)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LUTAccuracyWarning)
            lut = look.to_lut(frames=image).lut
        with torch.no_grad():
            errors = real_errors(lut, transform, look.per_pixel_input(image))
        report = lut.error_report
        rows.append({"image": name, "pixels": report.colours, "report_p99_9": report.p99_9, "report_max": report.max,
                     "real_p99_9": quantile_999(errors), "real_max": float(errors.max())})
    return rows


def span(ratios: list) -> str:
    """The lowest and highest of ``ratios``, as the tables show them."""
    return f"{min(ratios):.2f}–{max(ratios):.2f}"


def summary_table(looks: dict) -> list:
    """Per look: each figure the report states and its ratio to the real p99.9 on each picture of its footage, and the
    cause the report names when over its tolerance; then, per figure, how many ratios lie within :data:`MARGIN`."""
    header = " | ".join(f"{figure} | report / real, {len(rows)} {FIGURES[figure]}"
                        for figure, rows in by_figure(next(iter(looks.values()))["rows"]).items())
    lines = [f"| look | {header} | report's cause |", "| --- |" + " ---: | ---: |" * len(FIGURES) + " --- |"]
    for label, look in looks.items():
        cells = [f"{figures[0]['report']:.2f} | {span([r['report'] / r['real'] for r in figures])}"
                 for figures in by_figure(look["rows"]).values()]
        lines.append(f"| {label} | {' | '.join(cells)} | {(look['cause'] or 'within tolerance').split(' (')[0]} |")
    counts = []
    for figure in FIGURES:
        ratios = [row["report"] / row["real"] for look in looks.values() for row in by_figure(look["rows"])[figure]]
        within = sum(1 / MARGIN <= ratio <= MARGIN for ratio in ratios)
        counts.append(f"{figure} {within} of {len(ratios)} ({span(ratios)})")
    return lines + ["", f"Report / real within {MARGIN:g}× either way: {'; '.join(counts)}."]


def by_figure(rows: list) -> dict:
    """``rows`` of one look by the figure they are set against, in :data:`FIGURES`' order."""
    return {figure: [row for row in rows if row["figure"] == figure] for figure in FIGURES}


def frames_table(rows: list) -> list:
    lines = ["| image | pixels | report p99.9 | real p99.9 | report max | real max |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    lines += [f"| {r['image']} | {r['pixels']} | {r['report_p99_9']:.2f} | {r['real_p99_9']:.2f} | {r['report_max']:.2f} | "
              f"{r['real_max']:.2f} |" for r in rows]
    p99_9 = [r["report_p99_9"] / r["real_p99_9"] for r in rows]
    most = max(abs(r["report_max"] - r["real_max"]) for r in rows)
    return lines + ["", f"Report / real p99.9 {span(p99_9)} on {len(rows)} images; the report's max is the real max "
                        f"within {most:.2f} codes on every one."]


def markdown(report: dict) -> list:
    """The results page from the run's ``report``: the summary table marked ``ratios``, every look-and-picture pair,
    and the ``frames=`` table marked ``frames`` (:func:`~benchmarks.common.mark_table`)."""
    stamp = f"`{report['commit'][:7]}`{' with uncommitted changes' if report['modified'] else ''}"
    pairs = [f"| {label} | {row['figure']} | {row['picture']} | {row['report']:.2f} | {row['real']:.2f} | "
             f"{row['report'] / row['real']:.2f} |" for label, look in report["looks"].items() for row in look["rows"]]
    return ["# A baked LUT's report on each footage against its error on pictures of it, every pixel", "",
            " ".join(__doc__.split("\n\n")[3].split()).replace("``", "`").replace(":func:", ""), "",
            f"Made by `{report['command']}` at commit {stamp}. Every look baked on {report['lattice']}.", "",
            "## Each figure's ratio to the real p99.9 on pictures of its footage", "",
            "8-bit sRGB codes, p99.9; the report's figure, then report / real on each picture (lowest–highest); the cause the "
            "report names when over its tolerance (its whole text is in the JSON).", "",
            *mark_table("lut", "ratios", summary_table(report["looks"])), "",
            "## Every look and picture", "",
            "| look | figure | picture | report p99.9 | real p99.9 | report / real |", "| --- | --- | --- | ---: | ---: | ---: |",
            *pairs, "",
            "## The shipped look's `to_lut(frames=image)`: the report against every pixel", "",
            *mark_table("lut", "frames", frames_table(report["frames"]))]


def main(argv=None) -> None:
    out = argument_parser(__doc__).parse_args(argv).out
    torch.manual_seed(0)
    report = {"command": f"{COMMAND} --out {out}", **source_commit(), "looks": {}}
    lattices = set()
    for label, config in LOOKS.items():
        lut, rows = footage_rows(tg.PostFX.from_config(config).eval())
        lattices.add(f"`{lut.shaper}` {lut.size}³, {lut.interpolation}")
        report["looks"][label] = {"report": str(lut.error_report), "cause": lut.error_report.cause, "rows": rows}
    report["lattice"] = " and ".join(sorted(lattices))
    report["frames"] = framed_rows(tg.PostFX.from_config(LOOKS["cinematic (export/looks/cinematic.json)"]).eval())
    write_results(out, "lut_footage", report, markdown(report), report["command"])


if __name__ == "__main__":
    main()
