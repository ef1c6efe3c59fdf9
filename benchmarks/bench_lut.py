"""Speed of applying a 33³ LUT to a 1920×1080 float32 frame on CPU, side by side with OpenColorIO.

Every way of applying the same LUT (written once to a .cube file, so OpenColorIO reads exactly the
table torchgrade uses) is timed in this one process, round-robin: each of the repeated rounds runs
every method once, so a change of machine load hits all of them alike; the median round is reported
in ms, ms per megapixel, and as ratios to OpenColorIO's tetrahedral CPU processor and to a plain
tensor copy (the memory floor). Compile time of the ``compile=True`` paths is their first call, with an empty inductor cache.
Temporary memory is the peak resident memory a method adds beyond its input and output, per pixel,
measured in a child process run with glibc's mmap threshold fixed at 64 KiB (every large buffer a
fresh mapping; that slows allocation, so no timing is taken there) after resetting the kernel's
peak-RSS counter, each method warmed up (compiled) first.

Accuracy: a strong look (``ColorGrade(contrast=30, saturation=20, temperature=20)`` then
``ToneMap("aces")``) baked to 33³ LogC LUTs with each output encoding, and to 33³, 65³ and 129³ LUTs
whose lattice follows the scene, applied to every 4th pixel of the sample EXRs, against direct
float64 evaluation, in 8-bit sRGB code values (p99.9 and max). ``lut_floor.py`` asks what the best
possible 33³ table would do on the same pixels.

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

from benchmarks.metrics import srgb_codes  # noqa: E402
from torchgrade.io.cube import write_cube  # noqa: E402
from torchgrade.grade import ColorGrade  # noqa: E402
from torchgrade.io import read_exr  # noqa: E402
from torchgrade.lut import INTERPOLATIONS, LUT3D, OUTPUT_ENCODINGS, bake_lut, trilinear_grid_sample  # noqa: E402
from torchgrade.tonemap import ToneMap  # noqa: E402

COMMAND = ".venv/bin/python benchmarks/bench_lut.py"
HEIGHT, WIDTH, SIZE, RUNS = 1080, 1920, 33, 7
_MMAP_ENV = "MALLOC_MMAP_THRESHOLD_"
EXR_DIR = ROOT.parent / "shared" / "data" / "exr"
ACCURACY_IMAGES = ("Desk", "CandleGlass", "GoldenGate")


def look(image: torch.Tensor) -> torch.Tensor:
    """A non-separable look: channel cross-talk and a filmic-style curve."""
    r, g, b = image.unbind(-3)
    y = torch.stack((0.9 * r + 0.1 * g, g + 0.05 * b * r, 1.1 * b + 0.05 * r), dim=-3).clamp_min(0.0)
    return (y / (0.6 + y)) ** 1.2


def median_ms_round_robin(methods: dict, runs: int = RUNS) -> dict:
    """Median ms of each ``(run, prepare)`` in ``methods``, timing every method once per round."""
    times = {name: [] for name in methods}
    for _ in range(runs):
        for name, (run, prepare) in methods.items():
            prepare()
            start = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - start)
    return {name: 1000.0 * statistics.median(values) for name, values in times.items()}


def strong_look(aces: bool = False) -> torch.nn.Module:
    """The strong look LUT accuracy is measured with: ``ColorGrade(contrast=30, saturation=20, temperature=20)``, ``ToneMap("aces")``.

    ``aces=True`` grades in ACEScc/ACEScg as Unity does when ACES tone mapping is selected (``ColorGrade(aces=True)``).
    """
    return torch.nn.Sequential(ColorGrade(contrast=30.0, saturation=20.0, temperature=20.0, aces=aces), ToneMap("aces"))


def accuracy_image(name: str) -> torch.Tensor:
    """Every 4th pixel of a sample EXR's RGB, ``(1, 3, H, W)`` float32: the pixels accuracy is measured on."""
    return read_exr(EXR_DIR / f"{name}.exr")[:3, ::4, ::4].unsqueeze(0)


ACCURACY_LUTS = [(SIZE, "default", encoding) for encoding in OUTPUT_ENCODINGS] + [(size, "scene", "srgb") for size in (SIZE, 65, 129)]
"""(size, lattice domain, output encoding) of the LogC LUTs in the accuracy table: the default domain
(up to linear 58.86), or the scene's range (``bake_lut(scene=image)``)."""


def accuracy() -> list:
    """Errors of LogC LUTs (:data:`ACCURACY_LUTS`) of the strong look on the sample EXRs, in 8-bit sRGB code values."""
    look = strong_look()
    rows = []
    with torch.no_grad():
        for name in ACCURACY_IMAGES:
            image = accuracy_image(name)
            direct = srgb_codes(look(image.double()))
            for size, domain, encoding in ACCURACY_LUTS:
                lut = bake_lut(look, size=size, scene=image if domain == "scene" else None, output_encoding=encoding)
                for interpolation in INTERPOLATIONS:
                    error = (srgb_codes(lut(image, interpolation)) - direct).abs().flatten().numpy()
                    rows.append({"image": name, "size": size, "domain": domain, "output_encoding": encoding, "interpolation": interpolation,
                                 "p99_9": float(np.quantile(error, 0.999)), "max": float(error.max())})
    return rows


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
    if not measure_memory:  # time cold compiles: a fresh inductor cache, which the memory child then reuses
        inductor_cache = tempfile.TemporaryDirectory()
        os.environ["TORCHINDUCTOR_CACHE_DIR"] = inductor_cache.name

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

    def ocio_method(processor):
        return lambda: processor.applyRGB(buffer), restore

    def no_preparation():
        pass

    methods = {
        "plain tensor copy (memory floor)": (lambda: image.clone(), no_preparation),
        "grid_sample 5-D, naive": (lambda: trilinear_grid_sample(image.clamp(0, 1), lut.table), no_preparation),
    }
    for interpolation in ("tetrahedral", "trilinear"):
        methods[f"torchgrade {interpolation}, eager (default)"] = (lambda mode=interpolation: lut(image, mode), no_preparation)
        methods[f"torchgrade {interpolation}, compile=True"] = (lambda mode=interpolation: compiled(image, mode), no_preparation)
    for interpolation, processor in processors.items():
        methods[f"OpenColorIO CPU processor, {interpolation} (in place)"] = ocio_method(processor)

    compile_s = {}
    for name, (run, prepare) in methods.items():  # warm-up; the compiled paths compile here
        prepare()
        start = time.perf_counter()
        run()
        if "compile=True" in name:
            compile_s[name] = time.perf_counter() - start

    if measure_memory:  # child process: memory only, with every large buffer a fresh mapping
        memory = {}
        for name, (run, prepare) in methods.items():
            prepare()
            output_bytes = 0 if name.startswith("OpenColorIO") else frame_bytes
            memory[name] = temporary_bytes_per_pixel(run, output_bytes, pixels)
        print(json.dumps(memory))
        return
    child = subprocess.run([sys.executable, __file__, "--memory"], env={**os.environ, _MMAP_ENV: "65536"}, capture_output=True, text=True, check=True)
    memory = json.loads(child.stdout.strip().splitlines()[-1])
    medians = median_ms_round_robin(methods)
    results = []
    for name in methods:
        result = {"method": name, "ms": medians[name], "temporary_bytes_per_pixel": memory[name]}
        if name in compile_s:
            result["compile_s"] = compile_s[name]
        results.append(result)

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
        "statistic": "median of round-robin rounds",
        "threads": torch.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "torch": torch.__version__,
        "opencolorio": OCIO.__version__,
        "platform": platform.platform(),
        "note": "shared machine: other processes may have been running during the measurement",
        "results": results,
        "accuracy": accuracy() if EXR_DIR.is_dir() else [],
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
        f"Median of {report['runs']} round-robin rounds, {report['threads']} threads, torch {report['torch']}, "
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
    if report["accuracy"]:
        lines += [
            "",
            "## Accuracy of LogC LUTs of a strong look (every 4th pixel, 8-bit sRGB code values vs direct float64)",
            "",
            "Lattice domain: the default (up to linear 58.86), or the scene's range (`bake_lut(scene=image)`).",
            "",
            "| image | size | domain | output encoding | interpolation | p99.9 | max |",
            "| --- | ---: | --- | --- | --- | ---: | ---: |",
        ]
        for a in report["accuracy"]:
            lines.append(f"| {a['image']} | {a['size']}³ | {a['domain']} | {a['output_encoding']} | {a['interpolation']} | {a['p99_9']:.2f} | {a['max']:.1f} |")
    lines += ["", f"Reproduce: `{report['command']}`", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
