"""Exported looks on onnxruntime and OpenVINO vs PyTorch eager at 1920x1080, node counts before and after
constant folding, the per-pixel stage (grade + tone map) eager vs ``torch.compile``, and the whole look
under ``torch.compile(fullgraph=True)``.

    .venv/bin/python benchmarks/bench_onnx.py

Writes benchmarks/results/onnx.json and onnx.md. Latencies are the median of 5 runs after a warm-up,
batch 1, float32 in and out, CPU, in one process on this machine; the calls of one row alternate run by
run (:func:`benchmarks.common.median_ms`), so compare within a row.
"""

from __future__ import annotations

import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import torchgrade as tg  # noqa: E402
from benchmarks.common import median_ms  # noqa: E402

LOOK = ROOT / "export" / "looks" / "cinematic.json"
RESULTS = ROOT / "benchmarks" / "results"
HEIGHT, WIDTH, REPEATS = 1080, 1920, 5
COMMAND = ".venv/bin/python benchmarks/bench_onnx.py"
RUNTIMES = {"onnxruntime": ("onnxruntime", None), "openvino_f32": ("openvino", "f32"), "openvino_default": ("openvino", None)}


def eager(look: tg.PostFX, inputs):
    """The stateless look in PyTorch, as the graph computes it."""
    return (lambda: look.frame(*inputs)) if isinstance(inputs, tuple) else (lambda: look(inputs))


def measure(name: str, look: tg.PostFX, image: torch.Tensor, folder: Path, **options) -> dict:
    """Export ``look`` (as traced and folded); time every runtime and PyTorch eager alternately."""
    raw = tg.onnx.export(look, folder / f"{name}_raw.onnx", fold=False, **options)
    path = tg.onnx.export(look, folder / f"{name}.onnx", **options)
    inputs = tg.onnx.graph_inputs(look, image)
    calls = {}
    for label, (runtime, precision) in RUNTIMES.items():
        runner = tg.onnx.session(path, runtime, precision)
        calls[label] = lambda runner=runner, feeds=tg.onnx.feeds(runner, look, inputs): runner.run(None, feeds)
    calls["pytorch"] = eager(look, inputs)
    with torch.no_grad():
        medians = median_ms(calls, REPEATS)
    return {"nodes_traced": tg.onnx.node_count(raw), "nodes": tg.onnx.node_count(path),
            **{f"{label}_ms": round(ms, 1) for label, ms in medians.items()}}


def compiled(name: str, look: tg.PostFX, inputs, fullgraph: bool) -> dict:
    """Eager vs ``torch.compile`` of the same call, alternately; a compile that fails is reported, not raised."""
    call = eager(look, inputs)
    start = time.perf_counter()
    try:
        fast = torch.compile(call, fullgraph=fullgraph)
        with torch.no_grad():
            fast()
    except Exception as error:  # noqa: BLE001 - the table records why
        return {"error": f"{type(error).__name__}: {str(error).splitlines()[0][:120]}"}
    seconds = time.perf_counter() - start
    with torch.no_grad():
        medians = median_ms({"pytorch": call, "compiled": fast}, REPEATS)
    return {"pytorch_ms": round(medians["pytorch"], 1), "compiled_ms": round(medians["compiled"], 1),
            "eager_over_compiled": round(medians["pytorch"] / medians["compiled"], 2), "compile_s": round(seconds, 1)}


def table(report: dict) -> list:
    rows = report["results"]
    lines = [f"# ONNX export: {report['look']} at {WIDTH}x{HEIGHT}, median of {REPEATS}", "",
             f"`{COMMAND}` (torch {report['torch']}, {report['threads']} threads, CPU only: no GPU on this machine; "
             "OpenVINO's default precision on this CPU is bfloat16)", "",
             "| model | nodes as traced | nodes folded | onnxruntime ms | OpenVINO f32 ms | OpenVINO default ms | PyTorch eager ms |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    lines += [f"| {name} | {r['nodes_traced']} | {r['nodes']} | {r['onnxruntime_ms']} | {r['openvino_f32_ms']} | "
              f"{r['openvino_default_ms']} | {r['pytorch_ms']} |" for name, r in rows.items()]
    lines += ["", "| torch.compile | eager ms | compiled ms | eager / compiled | compile s |", "| --- | ---: | ---: | ---: | ---: |"]
    for name, r in report["compile"].items():
        lines.append(f"| {name} | failed: {r['error']} | | | |" if "error" in r else
                     f"| {name} | {r['pytorch_ms']} | {r['compiled_ms']} | {r['eager_over_compiled']} | {r['compile_s']} |")
    return lines


def main() -> int:
    torch.manual_seed(0)
    config = json.loads(LOOK.read_text())
    image = tg.scene.demo_scene(HEIGHT, WIDTH)
    look = tg.PostFX.from_config(config).eval()
    rows = {}
    with tempfile.TemporaryDirectory() as folder:
        for stage in config:
            rows[f"stage: {stage}"] = measure(stage, tg.PostFX.from_config({stage: config[stage]}).eval(), image, Path(folder))
        rows["full look"] = measure("full", look, image, Path(folder))
        baked = look.to_lut(33)
        for interpolation, backend in (("tetrahedral", "gather"), ("trilinear", "strip")):
            baked.interpolation = interpolation
            rows[f"full look, 33³ LUT {interpolation} ({backend})"] = measure(
                f"lut_{interpolation}_{backend}", baked, image, Path(folder), lut_backend=backend)
    per_pixel = tg.PostFX.from_config({"grade": config["grade"], "tonemap": config["tonemap"]}).eval()
    report = {
        "command": COMMAND, "look": str(LOOK.relative_to(ROOT)), "frame": [HEIGHT, WIDTH], "repeats": REPEATS,
        "torch": torch.__version__, "threads": torch.get_num_threads(), "machine": platform.processor() or platform.machine(),
        "gpu": "none", "results": rows,
        "compile": {
            "grade + tonemap (per-pixel stage)": compiled("per_pixel", per_pixel, image, fullgraph=False),
            "whole look, fullgraph=True": compiled("full", look, tg.onnx.graph_inputs(look, image), fullgraph=True),
        },
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "onnx.json").write_text(json.dumps(report, indent=2) + "\n")
    lines = table(report)
    (RESULTS / "onnx.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"\nreproduce: {COMMAND}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
