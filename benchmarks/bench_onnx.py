"""Exported looks on onnxruntime and OpenVINO vs PyTorch eager at 1920x1080 (the whole look also with its
per-pixel stages on the whole frame, ``strips=False``), node counts before and after constant folding, the
per-pixel stage (grade + tone map) eager vs ``torch.compile``, and the whole look under
``torch.compile(fullgraph=True)``.

    .venv/bin/python -m benchmarks onnx [--device cuda] [--out DIR]

Writes onnx.json and onnx.md to ``--out`` (default benchmarks/out; the committed ones with ``--out benchmarks/results``;
``--device cuda``: onnx_cuda.json and onnx_cuda.md, with
onnxruntime's CUDA provider and PyTorch on the GPU; OpenVINO runs on the CPU only and is left out there).
Latencies are the median of 9 runs after a warm-up, batch 1, float32 in and out, in one process on this
machine, host arrays in and out for onnxruntime; the calls of one row alternate run by run
(:func:`benchmarks.common.median_ms`), so compare within a row. One row runs the whole look on one thread
each (onnxruntime's intra-op threads, PyTorch's): a server that runs a session per core, and a figure
that a neighbour's load on the other core moves less.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import torch

import torchgrade as tg
from benchmarks.common import argument_parser, median_ms, write_results
from torchgrade.runtime.policy import one_thread

ROOT = Path(__file__).resolve().parents[1]

LOOK = ROOT / "export" / "looks" / "cinematic.json"
HEIGHT, WIDTH, REPEATS = 1080, 1920, 9
COMMAND = ".venv/bin/python -m benchmarks onnx"
RUNTIMES = {
    "cpu": {"onnxruntime": ("onnxruntime", None), "onnxruntime_no_spin": ("onnxruntime", None),
            "openvino_f32": ("openvino", "f32"), "openvino_default": ("openvino", None)},
    "cuda": {"onnxruntime": ("onnxruntime", None)},
}
"""The runtime columns of each device: ``{label: (runtime, OpenVINO precision hint)}``."""
COLUMNS = {"onnxruntime": "onnxruntime ms", "onnxruntime_no_spin": "onnxruntime, no spinning ms",
           "openvino_f32": "OpenVINO f32 ms", "openvino_default": "OpenVINO default ms"}


def parse_args(argv=None) -> argparse.Namespace:
    """``--device cpu`` (default) or ``cuda``, and ``--out DIR``.

    Examples:
        >>> parse_args(["--device", "cuda"]).device
        'cuda'
    """
    parser = argument_parser(__doc__)
    parser.add_argument("--device", choices=tuple(RUNTIMES), default="cpu", help="where onnxruntime and PyTorch run")
    return parser.parse_args(argv)


def results_stem(device: str) -> str:
    """The results files' name: ``onnx`` for the CPU, ``onnx_<device>`` otherwise.

    Examples:
        >>> results_stem("cpu"), results_stem("cuda")
        ('onnx', 'onnx_cuda')
    """
    return "onnx" if device == "cpu" else f"onnx_{device}"


def synchronizer(device: str):
    """What makes a timing wait for the device's queued work: ``torch.cuda.synchronize`` on CUDA, else None."""
    return torch.cuda.synchronize if device == "cuda" else None


def eager(look: tg.PostFX, inputs):
    """The stateless look in PyTorch, as the graph computes it."""
    return (lambda: look.frame(*inputs)) if isinstance(inputs, tuple) else (lambda: look(inputs))


def measure(name: str, look: tg.PostFX, image: torch.Tensor, folder: Path, device: str = "cpu", runtimes=None,
            threads=None, **options) -> dict:
    """Export ``look`` (as traced and folded); time ``runtimes`` (labels of ``device``'s, default all) and PyTorch
    eager alternately, each on ``threads`` CPU threads (None: its default)."""
    raw = tg.onnx.export(look, folder / f"{name}_raw.onnx", fold=False, **options)
    path = tg.onnx.export(look, folder / f"{name}.onnx", **options)
    inputs = tg.onnx.graph_inputs(look, image)
    calls = {}
    for label, (runtime, precision) in RUNTIMES[device].items():
        if runtimes is not None and label not in runtimes:
            continue
        on = device if runtime == "onnxruntime" else "cpu"
        runner = tg.onnx.session(path, runtime, precision, on, spin=not label.endswith("_no_spin"), threads=threads)
        feeds = tg.onnx.feeds(runner, look, inputs)
        calls[label] = lambda runner=runner, feeds=feeds: runner.run(None, feeds)
    on_device = tg.onnx.graph_inputs(look, image.to(device))
    calls["pytorch"] = eager(look.to(device), on_device)
    if threads == 1:
        calls["pytorch"] = lambda call=calls["pytorch"]: _on_one_thread(call)
    with torch.no_grad():
        medians = median_ms(calls, REPEATS, sync=synchronizer(device))
    look.cpu()
    return {"nodes_traced": tg.onnx.node_count(raw), "nodes": tg.onnx.node_count(path),
            **{f"{label}_ms": round(ms, 1) for label, ms in medians.items()}}


def _on_one_thread(call):
    with one_thread():
        return call()


def compiled(name: str, look: tg.PostFX, inputs, fullgraph: bool, device: str = "cpu") -> dict:
    """Eager vs ``torch.compile`` of the same call on ``device``, alternately; a compile that fails is reported, not raised."""
    inputs = inputs.to(device) if isinstance(inputs, torch.Tensor) else tuple(t.to(device) for t in inputs)
    call = eager(look.to(device), inputs)
    start = time.perf_counter()
    try:
        fast = torch.compile(call, fullgraph=fullgraph)
        with torch.no_grad():
            fast()
    except Exception as error:  # noqa: BLE001 - the table records why
        return {"error": f"{type(error).__name__}: {str(error).splitlines()[0][:120]}"}
    seconds = time.perf_counter() - start
    with torch.no_grad():
        medians = median_ms({"pytorch": call, "compiled": fast}, REPEATS, sync=synchronizer(device))
    return {"pytorch_ms": round(medians["pytorch"], 1), "compiled_ms": round(medians["compiled"], 1),
            "eager_over_compiled": round(medians["pytorch"] / medians["compiled"], 2), "compile_s": round(seconds, 1)}


def eager_profile(call, pixels: int, top: int = 10) -> dict:
    """Where one eager call spends its time (torch.profiler): ``{"passes": kernels that read a whole frame of
    ``pixels`` pixels or more, "ops": {aten op: [calls, own ms]}}`` for the ``top`` ops by own time."""
    from torch.profiler import ProfilerActivity, profile

    with torch.no_grad(), profile(activities=[ProfilerActivity.CPU], record_shapes=True) as trace:
        call()
    frame_sized = [e for e in trace.events() if not e.cpu_children
                   and any(math.prod(shape) >= pixels for shape in e.input_shapes if shape)]
    averages = sorted(trace.key_averages(), key=lambda e: -e.self_cpu_time_total)
    ops = {e.key: [e.count, round(e.self_cpu_time_total / 1000.0, 1)] for e in averages[:top]}
    return {"passes": len(frame_sized), "ops": ops}


def device_note(report: dict) -> str:
    """The results' second line: how they were run, on which device, under what load."""
    load = "load average {:.1f} at the start, {:.1f} at the end".format(*report["load_average"])
    if report["device"] == "cpu":
        where = ("CPU only: no GPU was available to measure onnxruntime's CUDA provider or PyTorch CUDA, so there is no "
                 "onnx_cuda.md (`--device cuda` writes it where there is one); OpenVINO's default precision on this CPU is bfloat16")
    else:
        where = f"{report['gpu']}, onnxruntime's CUDA provider fed host arrays"
    return (f"`{COMMAND}{'' if report['device'] == 'cpu' else ' --device ' + report['device']}` (torch {report['torch']}, "
            f"{report['threads']} CPU threads, {where}; {load} on {report['cores']} cores)")


def table(report: dict) -> list:
    rows = report["results"]
    labels = [*RUNTIMES[report["device"]], "pytorch"]
    heads = [COLUMNS.get(label, "PyTorch eager ms") for label in labels]
    lines = [f"# ONNX export: {report['look']} at {WIDTH}x{HEIGHT}, median of {REPEATS}", "", device_note(report), "",
             f"| model | nodes as traced | nodes folded | {' | '.join(heads)} |", "| --- |" + " ---: |" * (2 + len(heads))]
    lines += [f"| {name} | {r['nodes_traced']} | {r['nodes']} | " + " | ".join(str(r.get(f"{label}_ms", "–")) for label in labels) + " |"
              for name, r in rows.items()]
    lines += ["", "| torch.compile | eager ms | compiled ms | eager / compiled | compile s |", "| --- | ---: | ---: | ---: | ---: |"]
    for name, r in report["compile"].items():
        lines.append(f"| {name} | failed: {r['error']} | | | |" if "error" in r else
                     f"| {name} | {r['pytorch_ms']} | {r['compiled_ms']} | {r['eager_over_compiled']} | {r['compile_s']} |")
    profile = report.get("eager_profile")
    if profile:
        lines += ["", f"Eager grade + tone map, one call profiled: {profile['passes']} kernels over the whole frame "
                  "(kernels that read a whole frame); `torch.compile` fuses them into a few loops.", "",
                  "| aten op | calls | own ms |", "| --- | ---: | ---: |"]
        lines += [f"| {op} | {calls} | {ms} |" for op, (calls, ms) in profile["ops"].items()]
    return lines


def main(argv=None) -> int:
    args = parse_args(argv)
    device = args.device
    if device == "cuda" and not torch.cuda.is_available():
        print("--device cuda: PyTorch sees no CUDA device here", file=sys.stderr)
        return 2
    torch.manual_seed(0)
    config = json.loads(LOOK.read_text())
    image = tg.scene.demo_scene(HEIGHT, WIDTH)
    look = tg.PostFX.from_config(config).eval()
    load_start = os.getloadavg()[0]
    rows = {}
    with tempfile.TemporaryDirectory() as folder:
        for stage in config:
            rows[f"stage: {stage}"] = measure(stage, tg.PostFX.from_config({stage: config[stage]}).eval(), image, Path(folder), device)
        rows["full look"] = measure("full", look, image, Path(folder), device)
        rows["full look, whole-frame graph (strips=False)"] = measure("full_whole", look, image, Path(folder), device, strips=False)
        if device == "cpu":
            rows["full look, one thread each"] = measure("full_one_thread", look, image, Path(folder), device,
                                                         runtimes=("onnxruntime",), threads=1)
        baked = look.to_lut(33)
        for interpolation, backend in (("tetrahedral", "gather"), ("trilinear", "slices")):
            baked.interpolation = interpolation
            rows[f"full look, 33³ LUT {interpolation} ({backend})"] = measure(
                f"lut_{interpolation}_{backend}", baked, image, Path(folder), device, lut_backend=backend)
    per_pixel = tg.PostFX.from_config({"grade": config["grade"], "tonemap": config["tonemap"]}).eval()
    report = {
        "command": COMMAND, "device": device, "look": str(LOOK.relative_to(ROOT)), "frame": [HEIGHT, WIDTH], "repeats": REPEATS,
        "torch": torch.__version__, "threads": torch.get_num_threads(), "cores": os.cpu_count(),
        "machine": platform.processor() or platform.machine(),
        "gpu": torch.cuda.get_device_name() if device == "cuda" else "none", "results": rows,
        "compile": {
            "grade + tonemap (per-pixel stage)": compiled("per_pixel", per_pixel, image, False, device),
            "whole look, fullgraph=True": compiled("full", look, tg.onnx.graph_inputs(look, image), True, device),
        },
    }
    report["eager_profile"] = eager_profile(eager(per_pixel.to(device), image.to(device)), HEIGHT * WIDTH)
    report["load_average"] = [load_start, os.getloadavg()[0]]
    write_results(args.out, results_stem(device), report, table(report), f"{COMMAND}{'' if device == 'cpu' else ' --device ' + device}", device)
    return 0


if __name__ == "__main__":
    sys.exit(main())
