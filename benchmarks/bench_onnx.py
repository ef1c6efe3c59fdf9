"""onnxruntime vs PyTorch eager for the example look at 1920x1080, and ONNX node counts per stage.

    .venv/bin/python benchmarks/bench_onnx.py

Writes benchmarks/results/onnx.json and onnx.md. Latencies are the median of 5 runs after a warm-up,
batch 1, float32, CPU, in one process on this machine, onnxruntime and PyTorch alternating run by run
(:func:`benchmarks.common.median_ms`).
"""

from __future__ import annotations

import json
import platform
import sys
import tempfile
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


def graph_inputs(look: tg.PostFX, image: torch.Tensor):
    return (image, torch.zeros(1), torch.tensor(0.0)) if look.exposure is not None else image


def measure(name: str, look: tg.PostFX, image: torch.Tensor, folder: Path, **options) -> dict:
    """Export ``look``; time onnxruntime and the stateless look in PyTorch (as the graph computes it), alternately."""
    path = tg.onnx.export(look, folder / f"{name}.onnx", **options)
    inputs = graph_inputs(look, image)
    runner = tg.onnx.session(path)
    feeds = tg.onnx.feeds(runner, look, inputs)
    calls = {
        "onnxruntime": lambda: runner.run(None, feeds),
        "pytorch": (lambda: look.frame(*inputs)) if isinstance(inputs, tuple) else (lambda: look(inputs)),
    }
    medians = median_ms(calls, REPEATS)
    return {
        "nodes": tg.onnx.node_count(path),
        "onnxruntime_ms": round(medians["onnxruntime"], 1),
        "pytorch_ms": round(medians["pytorch"], 1),
    }


def main() -> int:
    torch.manual_seed(0)
    config = json.loads(LOOK.read_text())
    image = tg.scene.demo_scene(HEIGHT, WIDTH)
    look = tg.PostFX.from_config(config)
    rows = {}
    with tempfile.TemporaryDirectory() as folder:
        for stage in config:
            rows[f"stage: {stage}"] = measure(stage, tg.PostFX.from_config({stage: config[stage]}), image, Path(folder))
        rows["full look"] = measure("full", look, image, Path(folder))
        baked = look.to_lut(33)
        for interpolation, backend in (("tetrahedral", "gather"), ("trilinear", "strip"), ("trilinear", "volume")):
            baked.interpolation = interpolation
            rows[f"full look, 33³ LUT {interpolation} ({backend})"] = measure(
                f"lut_{interpolation}_{backend}", baked, image, Path(folder), lut_backend=backend)
    report = {
        "command": COMMAND, "look": str(LOOK.relative_to(ROOT)), "frame": [HEIGHT, WIDTH], "repeats": REPEATS,
        "torch": torch.__version__, "threads": torch.get_num_threads(), "machine": platform.processor() or platform.machine(),
        "results": rows,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "onnx.json").write_text(json.dumps(report, indent=2) + "\n")
    lines = [f"# ONNX export: {report['look']} at {WIDTH}x{HEIGHT}, median of {REPEATS}", "",
             f"`{COMMAND}` (torch {torch.__version__}, {report['threads']} threads)", "",
             "| model | ONNX nodes | onnxruntime ms | PyTorch eager ms |", "| --- | ---: | ---: | ---: |"]
    lines += [f"| {name} | {r['nodes']} | {r['onnxruntime_ms']} | {r['pytorch_ms']} |" for name, r in rows.items()]
    (RESULTS / "onnx.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"\nreproduce: {COMMAND}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
