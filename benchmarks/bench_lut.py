"""Speed of applying a 33³ LUT to a 1920×1080 float32 frame on CPU, side by side with OpenColorIO.

Every way of applying the same LUT (written once to a .cube file, so OpenColorIO reads exactly the
table torchgrade uses) is timed as the median of repeated runs in this one process, and reported in
ms, ms per megapixel, and as ratios to OpenColorIO's tetrahedral CPU processor and to a plain tensor
copy (the memory floor). Temporary memory is the peak resident memory a method adds beyond its input
and output, per pixel, measured in a child process run with glibc's mmap threshold fixed at 64 KiB
(every large buffer a fresh mapping; that slows allocation, so no timing is taken there) after
resetting the kernel's peak-RSS counter; the compiled kernels are not measured (n/a) to spare a
second compilation.

Run: ``.venv/bin/python benchmarks/bench_lut.py`` (writes benchmarks/results/lut.json and lut.md).
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from torchgrade.io.cube import write_cube  # noqa: E402
from torchgrade.lut import LUT3D, bake_lut, trilinear_grid_sample  # noqa: E402

COMMAND = ".venv/bin/python benchmarks/bench_lut.py"
HEIGHT, WIDTH, SIZE, RUNS = 1080, 1920, 33, 7
_MMAP_ENV = "MALLOC_MMAP_THRESHOLD_"


def look(image: torch.Tensor) -> torch.Tensor:
    """A non-separable look: channel cross-talk and a filmic-style curve."""
    r, g, b = image.unbind(-3)
    y = torch.stack((0.9 * r + 0.1 * g, g + 0.05 * b * r, 1.1 * b + 0.05 * r), dim=-3).clamp_min(0.0)
    return (y / (0.6 + y)) ** 1.2


def median_ms(run, prepare=lambda: None, runs: int = RUNS) -> float:
    prepare()
    run()  # warm-up
    times = []
    for _ in range(runs):
        prepare()
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return 1000.0 * statistics.median(times)


def _status_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


def temporary_bytes_per_pixel(run, output_bytes: int, pixels: int):
    """Peak resident memory during ``run()`` beyond what was resident before and its output."""
    try:
        Path("/proc/self/clear_refs").write_text("5")  # reset the peak-RSS counter (Linux >= 4.0)
    except OSError:
        return None
    before = _status_kib("VmRSS")
    result = run()
    peak = _status_kib("VmHWM")
    del result
    return max(0.0, ((peak - before) * 1024 - output_bytes) / pixels)


def main() -> None:
    import PyOpenColorIO as OCIO

    measure_memory = "--memory" in sys.argv

    torch.manual_seed(0)
    image = torch.rand(1, 3, HEIGHT, WIDTH) * 1.1 - 0.05
    pixels, frame_bytes = HEIGHT * WIDTH, image.numel() * 4
    lut = bake_lut(look, size=SIZE, shaper="linear")
    lut.table = lut.table.float()
    compiled = LUT3D(lut.table, shaper="linear", compile=True)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "bench.cube")
        write_cube(path, lut)
        config = OCIO.Config.CreateRaw()
        processors = {
            name: config.getProcessor(OCIO.FileTransform(src=path, interpolation=mode)).getDefaultCPUProcessor()
            for name, mode in (("tetrahedral", OCIO.INTERP_TETRAHEDRAL), ("trilinear", OCIO.INTERP_LINEAR))
        }
    source = np.ascontiguousarray(image[0].permute(1, 2, 0).numpy())
    buffer = np.empty_like(source)

    def restore():
        np.copyto(buffer, source)

    methods = {
        "plain tensor copy (memory floor)": (lambda: image.clone(), None),
        "grid_sample 5-D, naive": (lambda: trilinear_grid_sample(image.clamp(0, 1), lut.table), None),
        "torchgrade trilinear, eager": (lambda: lut(image, "trilinear"), None),
        "torchgrade tetrahedral, eager": (lambda: lut(image, "tetrahedral"), None),
    }
    if measure_memory:  # child process: memory only, with every large buffer a fresh mapping
        memory = {name: temporary_bytes_per_pixel(run, frame_bytes, pixels) for name, (run, _) in methods.items()}
        for interpolation, processor in processors.items():
            restore()
            memory[f"OpenColorIO CPU processor, {interpolation} (in place)"] = temporary_bytes_per_pixel(lambda: processor.applyRGB(buffer), 0, pixels)
        print(json.dumps(memory))
        return
    child = subprocess.run([sys.executable, __file__, "--memory"], env={**os.environ, _MMAP_ENV: "65536"}, capture_output=True, text=True, check=True)
    memory = json.loads(child.stdout.strip().splitlines()[-1])
    results = []
    for name, (run, prepare) in methods.items():
        results.append({"method": name, "ms": median_ms(run, prepare or (lambda: None)), "temporary_bytes_per_pixel": memory[name]})
    for interpolation in ("tetrahedral", "trilinear"):
        start = time.perf_counter()
        compiled(image, interpolation)
        compile_s = time.perf_counter() - start
        ms = median_ms(lambda: compiled(image, interpolation))
        results.append({"method": f"torchgrade {interpolation}, torch.compile", "ms": ms, "temporary_bytes_per_pixel": None, "compile_s": compile_s})
    for interpolation, processor in processors.items():
        name = f"OpenColorIO CPU processor, {interpolation} (in place)"
        results.append({"method": name, "ms": median_ms(lambda: processor.applyRGB(buffer), restore), "temporary_bytes_per_pixel": memory[name]})

    ocio = next(r["ms"] for r in results if r["method"].startswith("OpenColorIO CPU processor, tetrahedral"))
    copy = results[0]["ms"]
    for r in results:
        r["ms_per_megapixel"] = r["ms"] / (pixels / 1e6)
        r["ratio_to_ocio_tetrahedral"] = r["ms"] / ocio
        r["ratio_to_copy"] = r["ms"] / copy
    report = {
        "command": COMMAND,
        "frame": f"{WIDTH}x{HEIGHT} float32, 1 frame",
        "lut": f"{SIZE}^3, linear shaper",
        "runs": RUNS,
        "statistic": "median",
        "threads": torch.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "torch": torch.__version__,
        "opencolorio": OCIO.__version__,
        "platform": platform.platform(),
        "note": "shared machine: other processes may have been running during the measurement",
        "results": results,
    }
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "lut.json").write_text(json.dumps(report, indent=2) + "\n")
    (out / "lut.md").write_text(markdown(report))
    print(markdown(report))
    print(f"reproduce: {COMMAND}")


def markdown(report: dict) -> str:
    lines = [
        f"# Applying a {report['lut']} LUT to {report['frame']} on CPU",
        "",
        f"Median of {report['runs']} runs, {report['threads']} threads, torch {report['torch']}, "
        f"OpenColorIO {report['opencolorio']}. {report['note'].capitalize()}.",
        "",
        "| method | ms | ms/MP | × OCIO tetrahedral | × copy | temporary bytes/pixel |",
        "| --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in report["results"]:
        memory = "n/a" if r["temporary_bytes_per_pixel"] is None else f"{r['temporary_bytes_per_pixel']:.0f}"
        compile_note = f" (compile {r['compile_s']:.0f} s)" if "compile_s" in r else ""
        lines.append(
            f"| {r['method']}{compile_note} | {r['ms']:.1f} | {r['ms_per_megapixel']:.1f} | "
            f"{r['ratio_to_ocio_tetrahedral']:.2f} | {r['ratio_to_copy']:.1f} | {memory} |"
        )
    lines += ["", f"Reproduce: `{report['command']}`", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
