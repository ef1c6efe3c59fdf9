"""The suite's report: the markdown table of every row, the speed-vs-accuracy (Pareto) plot and the scaling plot.

Part of ``.venv/bin/python benchmarks/run.py [--quick] [--out DIR]``, which writes ``results.md``,
``pareto.png`` and ``scaling.png`` with these beside ``results.json``.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

import torch

from benchmarks.suite import workload
from benchmarks.suite.methods import PEER

ERROR_FLOOR = 1e-3
"""Errors below this (the float64 reference's 0) are drawn at it on the log axis."""


def fmt(value, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def row_note(record: dict) -> str:
    notes = []
    if "domain_top_linear" in record:
        notes.append(f"lattice up to linear {record['domain_top_linear']:g}")
    if "compile_s" in record:
        notes.append(f"compile {record['compile_s']:.0f} s")
    if "export_s" in record:
        notes.append(f"export {record['export_s']:.0f} s, {record['onnx_nodes']} nodes")
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


def markdown(report: dict) -> str:
    megapixels = workload.FRAME[0] * workload.FRAME[1] / 1e6
    base = ", ".join(f"{name} {ms / megapixels:.1f} ms/MP" for name, ms in report["baselines"].items())
    m = report["machine"]
    return "\n".join([
        f"# torchgrade benchmark ({'quick' if report['quick'] else 'full'}, {report['device']})",
        "",
        f"`{report['command']}` — {m['cpu_count']} CPUs, {m['torch_threads']} torch threads, torch {m['torch']}, "
        f"onnxruntime {m['onnxruntime']}, OpenColorIO {m['opencolorio']}; {report['wall_s']:.0f} s in all.",
        "",
        "Speed: the timed part of each row on a 1920×1080 frame, median of "
        f"{report['runs']} runs; × copy and × OCIO are ratios to a plain frame copy and to {PEER}, measured in this run. "
        f"Per-pixel rows exclude bloom, which every look adds: {base}.",
        f"Accuracy: the whole look on {', '.join(report['scenes'])} against the float64 look; "
        f"ΔE2000 over {report['delta_e_samples']} sampled pixels. Peak MiB: memory the timed part adds at 1920×1080.",
        "",
        markdown_table(report["rows"]),
        "",
    ])


def machine() -> dict:
    import onnxruntime
    import PyOpenColorIO as OCIO

    return {"cpu_count": os.cpu_count(), "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
            "onnxruntime": onnxruntime.__version__, "opencolorio": OCIO.__version__, "platform": platform.platform()}


def family_colours() -> dict:
    return {"direct": "tab:blue", "lut": "tab:orange", "torch.compile": "tab:green", "onnxruntime": "tab:purple",
            "opencolorio": "tab:red"}


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


def plot_pareto(records: list, path: Path) -> None:
    fig, ax = _pyplot().subplots(figsize=(9, 6), dpi=90)
    points = []
    for family, colour in family_colours().items():
        rows = [r for r in records if r.get("family") == family and r.get("timed") == "per-pixel stage" and "ms" in r]
        xs = [r["ms_per_megapixel"] for r in rows]
        ys = [max(r["p999_error_8bit"], ERROR_FLOOR) for r in rows]
        ax.scatter(xs, ys, s=22, color=colour, label=family, alpha=0.8)
        points += [(x, y, r["method"]) for x, y, r in zip(xs, ys, rows)]
    front = pareto_front(points)
    ax.plot([p[0] for p in front], [p[1] for p in front], color="black", lw=1, ls="--", label="Pareto front")
    for rank, (ms, error, name) in enumerate(front):  # staggered: front points often share an error
        ax.annotate(name, (ms, error), fontsize=7, xytext=(4, 3 - 10 * (rank % 4)), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("per-pixel stage, ms per megapixel at 1920×1080 (log)")
    ax.set_ylabel(f"whole look, 99.9th percentile error, 8-bit sRGB codes (log; 0 drawn at {ERROR_FLOOR})")
    ax.set_title("Speed vs accuracy of the look's per-pixel stage")
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
