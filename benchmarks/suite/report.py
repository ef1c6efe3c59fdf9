"""The suite's report: the markdown table of every row, advice computed from it, the warnings the run raised,
the speed-vs-accuracy (Pareto) plot and the scaling plot.

Part of ``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``, which writes ``results.md``,
``pareto.png`` and ``scaling.png`` with these beside ``results.json``.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from benchmarks.suite import workload
from benchmarks.suite.measure import LIVE
from benchmarks.suite.methods import HDR_UNUSABLE, PEER

ERROR_FLOOR = 1e-3
"""Errors below this (the float64 reference's 0) are drawn at it on the log axis."""
EXACT_CODES = 1.0
"""An error (8-bit sRGB codes) a row may reach and still count as the look: training asks it of the max, serving
and baking of the 99.9th percentile."""


def fmt(value, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def row_note(record: dict) -> str:
    notes = []
    if record.get("shaper") == HDR_UNUSABLE:
        notes.append("clips above 1: unusable for HDR")
    if "domain_top_linear" in record:
        notes.append(f"lattice up to linear {record['domain_top_linear']:g}")
    if "compile_s" in record:
        notes.append(f"compile {record['compile_s']:.0f} s")
    if "export_s" in record:
        notes.append(f"export {record['export_s']:.0f} s, {record['onnx_nodes']} nodes")
    if "did not compile" in record.get("lookup_form", ""):
        notes.append(record["lookup_form"])
    if "error" in record:
        notes.append(f"failed: {record['error']}")
    return "; ".join(notes)


def markdown_table(records: list) -> str:
    lines = ["| method | timed | ms/MP | × copy | × OCIO | p99.9 err (8-bit) | max err (8-bit) | mean ΔE2000 | peak MiB | note |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for r in records:
        lines.append(
            f"| {r['method']} | {r.get('timed', '')} | {fmt(r.get('ms_per_megapixel'), 1)} | {fmt(r.get('ratio_to_copy'), 1)} | "
            f"{fmt(r.get('ratio_to_opencolorio'))} | {fmt(r.get('p999_error_8bit'))} | {fmt(r.get('max_error_8bit'))} | "
            f"{fmt(r.get('mean_delta_e2000'), 3)} | {fmt(r.get('peak_memory_mb'), 0)} | {row_note(r)} |")
    return "\n".join(lines)


def timed(records: list, keep) -> list:
    """The records with a time that ``keep(record)`` accepts."""
    return [r for r in records if "ms" in r and keep(r)]


def fastest(records: list, keep):
    return min(timed(records, keep), key=lambda r: r["ms"], default=None)


def summary(record: dict) -> str:
    return (f"{record['method']} ({record['ms_per_megapixel']:.1f} ms/MP, p99.9 {record['p999_error_8bit']:.2f}, "
            f"max {record['max_error_8bit']:.2f} codes)")


def per_pixel(record: dict) -> bool:
    return record["timed"] == "per-pixel stage"


def training_advice(records: list) -> str:
    """The fastest PyTorch per-pixel stage within :data:`EXACT_CODES` of float64 everywhere (gradients reach the controls)."""
    torch_rows = lambda r: per_pixel(r) and r["family"] in ("direct", "torch.compile")  # noqa: E731
    exact = fastest(records, lambda r: torch_rows(r) and r["max_error_8bit"] <= EXACT_CODES)
    quickest = fastest(records, torch_rows)
    if exact is None:
        return "Training augmentation: no PyTorch row stayed within 1 code of float64."
    line = f"Training augmentation: {summary(exact)}"
    if quickest is not exact:
        line += f"; {quickest['method']} takes {quickest['ms'] / exact['ms']:.2f}× its time but is up to {quickest['max_error_8bit']:.1f} codes off"
    return line + "."


def serving_advice(records: list, baselines: dict) -> str:
    """The fastest per-pixel stage of any runtime within :data:`EXACT_CODES` at p99.9, and what the fastest HDR-capable row gives up."""
    exact = fastest(records, lambda r: per_pixel(r) and r["p999_error_8bit"] <= EXACT_CODES)
    quickest = min(hdr_choices(records), key=lambda r: r["ms"], default=None)
    live = f"plus the live {LIVE.removesuffix(' float32')} ({baselines[LIVE] / (workload.FRAME[0] * workload.FRAME[1] / 1e6):.1f} ms/MP)"
    if exact is None:
        return f"Serving: no row stayed within 1 code at p99.9; the fastest is {summary(quickest)}, {live}."
    line = f"Serving: {summary(exact)}, {live}"
    if quickest is not exact:
        line += f"; {quickest['method']} takes {quickest['ms'] / exact['ms']:.2f}× its time at p99.9 {quickest['p999_error_8bit']:.2f} codes"
    return line + "."


def baking_advice(records: list) -> str:
    """The most accurate HDR-capable LUT row (p99.9 as shown, then time), against the default bake looked up
    tetrahedrally (its faster form)."""
    luts = timed(records, lambda r: per_pixel(r) and r["family"] == "lut" and r.get("shaper") != HDR_UNUSABLE)
    if not luts:
        return "Baking a LUT: no LUT row was measured."
    best = min(luts, key=lambda r: (round(r["p999_error_8bit"], 2), r["ms"]))  # a tie as the table shows it: the faster
    default = fastest(luts, lambda r: r.get("default_bake") and r["interpolation"] == "tetrahedral")
    line = f"Baking a LUT: {summary(best)}"
    if default is not None and default is not best:
        line += (f"; the default bake ({default['shaper']}, {default['lut_size']}³ tetrahedral): p99.9 "
                 f"{default['p999_error_8bit']:.2f}, max {default['max_error_8bit']:.2f} codes")
    return line + "."


def advice(records: list, baselines: dict) -> list:
    """One line per use (training, serving, baking), computed from this run's records."""
    return [training_advice(records), serving_advice(records, baselines), baking_advice(records)]


def warning_records(caught: list) -> list:
    """Warnings caught by ``warnings.catch_warnings(record=True)``, one entry per distinct message with its count."""
    counts = Counter((w.category.__name__, str(w.message)) for w in caught)
    return [{"category": category, "message": message, "count": count} for (category, message), count in counts.items()]


def check_line(check) -> str:
    if check is None:
        return "Check: the whole-look or per-pixel float32 row was not timed."
    return (f"Check: the eager whole look took {check['whole_look_ms']:.0f} ms, its parts the live stages {check['live_ms']:.0f} ms + "
            f"per-pixel stage {check['per_pixel_ms']:.0f} ms; per round, whole look / parts = {check['whole_over_parts']:.2f} (median)"
            + (": below 1, so this run's timings are not to be trusted." if check["whole_over_parts"] < 1 else "."))


def provenance(report: dict) -> str:
    """Which code a run measured, with which command, and how long it took.

    Examples:
        >>> provenance({"commit": "0123456789ab", "modified": True, "command": "python -m benchmarks suite",
        ...             "wall_s": 30.4, "cpu_s": 51.0})
        'Commit `0123456` with uncommitted changes, `python -m benchmarks suite`: 30 s (51 s of CPU time).'
    """
    commit = f"Commit `{report['commit'][:7]}`" if report.get("commit") else "Not a git checkout"
    changes = " with uncommitted changes" if report.get("modified") else ""
    return f"{commit}{changes}, `{report['command']}`: {report['wall_s']:.0f} s ({report['cpu_s']:.0f} s of CPU time)."


def baselines_text(report: dict) -> str:
    """The baselines' ms per megapixel, as a list in words."""
    megapixels = workload.FRAME[0] * workload.FRAME[1] / 1e6
    return ", ".join(f"{name} {ms / megapixels:.1f} ms/MP" for name, ms in report["baselines"].items())


def markdown(report: dict) -> list:
    """The report as markdown lines: method, table, check, advice, warnings."""
    warned = [f"- {w['category']} ×{w['count']}: {w['message']}" for w in report["warnings"]] or ["none"]
    return [
        f"# torchgrade benchmark ({'quick' if report['quick'] else 'full'}, {report['device']})",
        "",
        provenance(report),
        "",
        "Speed: the timed part of each row on a 1920×1080 frame, every row and baseline alternated in one session, median of "
        f"{report['runs']} rounds; × copy and × OCIO are medians of each round's ratio to a plain frame copy and to {PEER}. "
        f"Per-pixel rows leave out the live stages, which every look adds: {baselines_text(report)}.",
        f"Accuracy: the whole look on {', '.join(report['scenes'])} against the float64 look; "
        f"ΔE2000 over {report['delta_e_samples']} sampled pixels. Peak MiB: memory the timed part adds at 1920×1080.",
        "",
        markdown_table(report["rows"]),
        "",
        check_line(report["check"]),
        "",
        "## Which method for which use (from this run)",
        "",
        *[f"- {line}" for line in report["advice"]],
        "",
        "## Warnings raised during the run",
        "",
        *warned,
    ]


SHORT_WIDTH = 64
"""Characters of a method's name the terminal table shows."""


def short_table(report: dict) -> str:
    """The run for a terminal: each row's ms/MP, × OCIO and errors, then the provenance line."""
    lines = [f"{'method':{SHORT_WIDTH}} {'ms/MP':>7} {'×OCIO':>6} {'p99.9':>6} {'max':>6} {'ΔE':>6}"]
    for r in report["rows"]:
        if "error" in r:
            lines.append(f"{r['method'][:SHORT_WIDTH]:{SHORT_WIDTH}} failed: {r['error']}")
            continue
        lines.append(f"{r['method'][:SHORT_WIDTH]:{SHORT_WIDTH}} {fmt(r.get('ms_per_megapixel'), 1):>7} "
                     f"{fmt(r.get('ratio_to_opencolorio')):>6} {fmt(r['p999_error_8bit']):>6} {fmt(r['max_error_8bit']):>6} "
                     f"{fmt(r['mean_delta_e2000'], 3):>6}")
    return "\n".join([*lines, "", provenance(report)])


def family_colours() -> dict:
    return {"direct": "tab:blue", "lut": "tab:orange", "torch.compile": "tab:green", "onnxruntime": "tab:purple",
            "openvino": "tab:brown", "opencolorio": "tab:red"}


def pareto_front(points: list) -> list:
    """The points no other point beats in both time and error, fastest first: ``[(ms, error, name), ...]``."""
    front, best = [], float("inf")
    for ms, error, name in sorted(points):
        if error < best:
            front.append((ms, error, name))
            best = error
    return front


def _pyplot():
    """matplotlib's pyplot on the file-only Agg backend (no display on benchmark machines)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path)
    _pyplot().close(fig)


def hdr_choices(records: list) -> list:
    """The rows the Pareto plot offers: timed per-pixel rows, without linear-shaper LUTs (they clip HDR input)."""
    return timed(records, lambda r: per_pixel(r) and r.get("shaper") != HDR_UNUSABLE)


def plot_pareto(records: list, path: Path) -> None:
    """:func:`hdr_choices` by time and error, the Pareto front labelled, the default bake's rows drawn as diamonds."""
    fig, ax = _pyplot().subplots(figsize=(9, 6), dpi=90)
    points, choices = [], hdr_choices(records)
    for family, colour in family_colours().items():
        rows = [r for r in choices if r["family"] == family]
        for default in (False, True):
            drawn = [r for r in rows if bool(r.get("default_bake")) == default]
            xs = [r["ms_per_megapixel"] for r in drawn]
            ys = [max(round(r["p999_error_8bit"], 2), ERROR_FLOOR) for r in drawn]  # as the table shows them
            label = f"{family}, default bake" if default else family
            ax.scatter(xs, ys, s=40 if default else 22, color=colour, marker="D" if default else "o",
                       edgecolors="black" if default else "none", label=label if drawn else None, alpha=0.8)
            points += [(x, y, r["method"]) for x, y, r in zip(xs, ys, drawn)]
    front = pareto_front(points)
    ax.plot([p[0] for p in front], [p[1] for p in front], color="black", lw=1, ls="--", label="Pareto front")
    for rank, (ms, error, name) in enumerate(front):  # staggered: front points often share an error
        ax.annotate(name, (ms, error), fontsize=7, xytext=(4, 3 - 10 * (rank % 4)), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("per-pixel stage, ms per megapixel at 1920×1080 (log)")
    ax.set_ylabel(f"whole look, 99.9th percentile error, 8-bit sRGB codes (log; 0 drawn at {ERROR_FLOOR})")
    ax.set_title(f"Speed vs accuracy of the look's per-pixel stage (HDR-capable rows; no {HDR_UNUSABLE}-shaper LUT)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    _save(fig, path)


def plot_scaling(points: list, path: Path) -> None:
    fig, (by_size, by_batch) = _pyplot().subplots(1, 2, figsize=(10, 4), dpi=90)
    for name in dict.fromkeys(p["path"] for p in points):
        sizes = [p for p in points if p["path"] == name and p["kind"] == "resolution"]
        batches = [p for p in points if p["path"] == name and p["kind"] == "batch"]
        by_size.plot([p["height"] * p["width"] / 1e6 for p in sizes], [p["ms"] for p in sizes], marker="o", label=name)
        by_batch.plot([p["batch"] for p in batches], [p["ms_per_megapixel"] for p in batches], marker="o", label=name)
    by_size.set(xscale="log", yscale="log", xlabel="megapixels (256² … largest)", ylabel="ms per frame", title="time vs resolution")
    by_batch.set(xscale="log", xlabel=f"batch size ({workload.BATCH_SIDE}²)", ylabel="ms per megapixel", title="time vs batch size")
    by_batch.set_xticks(workload.BATCHES, [str(b) for b in workload.BATCHES])
    by_batch.set_xticks([], minor=True)  # no "3×10⁰" labels between the batch sizes
    by_batch.set_ylim(bottom=0)
    for ax in (by_size, by_batch):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    _save(fig, path)
