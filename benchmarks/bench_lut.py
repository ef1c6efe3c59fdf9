"""Speed of applying a 33³ LUT to a 1920×1080 float32 frame on CPU, side by side with OpenColorIO.

Every way of applying the same LUT (written once to a .cube file, so OpenColorIO reads exactly the
table torchgrade uses) is timed in this one process, round-robin: each of the repeated rounds runs
every method once, so a change of machine load hits all of them alike; the median round is reported
in ms, ms per megapixel, and as ratios to OpenColorIO's tetrahedral CPU processor and to a plain
tensor copy (the memory floor). Compile time of the ``compile=True`` paths is their first call, with an empty inductor cache.
Temporary memory is the peak resident memory a method adds beyond its input and output, per pixel,
measured in a child process with glibc's mmap threshold fixed at 64 KiB (every large buffer a
fresh mapping; that slows allocation, so no timing is taken there) after resetting the kernel's
peak-RSS counter, each method warmed up (compiled) first (:mod:`benchmarks.common`).

Accuracy: a strong look (``ColorGrade(contrast=30, saturation=20, temperature=20)`` then
``ToneMap("aces")``, or with post-exposure 0.5 then ``ToneMap("neutral")``) baked to the LUTs of
:data:`ACCURACY_LUTS` (the former default ``logc_hdr``, LogC on its default, full or the scene's lattice,
fitted shapers), applied to every
4th pixel of the sample EXRs, against direct float64 evaluation, in 8-bit sRGB code values (p99.9
and max), beside each bake's own error report. ``lut_floor.py`` asks what the best
possible 33³ table would do on the same pixels.

Run: ``.venv/bin/python -m benchmarks lut [--out DIR]`` (writes lut.json and lut.md to ``--out``, default
benchmarks/out; the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

import torchgrade as tg
from benchmarks.common import (
    EXR_DIR, argument_parser, map_large_buffers, median_ms, ocio_in_place, ocio_processor, peak_rss_mb, run_and_reset, sample_exr, write_results)
from benchmarks.metrics import srgb_codes
from torchgrade.lut import INTERPOLATIONS, OUTPUT_ENCODINGS
from torchgrade.lut.kernels import trilinear_grid_sample

ROOT = Path(__file__).resolve().parents[1]

COMMAND = ".venv/bin/python -m benchmarks lut"
HEIGHT, WIDTH, SIZE, RUNS = 1080, 1920, 33, 7
ACCURACY_IMAGES = ("Desk", "CandleGlass", "GoldenGate")


def look(image: torch.Tensor) -> torch.Tensor:
    """A non-separable look: channel cross-talk and a filmic-style curve."""
    r, g, b = image.unbind(-3)
    y = torch.stack((0.9 * r + 0.1 * g, g + 0.05 * b * r, 1.1 * b + 0.05 * r), dim=-3).clamp_min(0.0)
    return (y / (0.6 + y)) ** 1.2


def strong_look(aces: bool = False, tonemap: str = "aces") -> torch.nn.Module:
    """The strong look LUT accuracy is measured with: ``ColorGrade(contrast=30, saturation=20, temperature=20)``, ``ToneMap("aces")``.

    ``aces=True`` grades in ACEScc/ACEScg as Unity does when ACES tone mapping is selected (``ColorGrade(aces=True)``).
    ``tonemap="neutral"`` adds post-exposure 0.5 and ends with Neutral instead.
    """
    exposure = 0.5 if tonemap == "neutral" else 0.0
    grade = tg.ColorGrade(contrast=30.0, saturation=20.0, temperature=20.0, post_exposure=exposure, aces=aces)
    return torch.nn.Sequential(grade, tg.ToneMap(tonemap))


def accuracy_image(name: str) -> torch.Tensor:
    """Every 4th pixel of a sample EXR's RGB, ``(1, 3, H, W)`` float32: the pixels accuracy is measured on."""
    return sample_exr(name)[..., ::4, ::4]


ACCURACY_LUTS = ([("aces", SIZE, shaper, "default", encoding) for shaper in ("logc_hdr", "logc") for encoding in OUTPUT_ENCODINGS]
                 + [("aces", SIZE, "logc", "full", "srgb")]
                 + [("aces", size, "logc", "scene", "srgb") for size in (SIZE, 65, 129)]
                 + [("aces", SIZE, "fitted", domain, "srgb") for domain in ("default", "scene")]
                 + [("neutral", SIZE, shaper, domain, "srgb") for shaper, domain in
                    (("logc_hdr", "default"), ("logc", "default"), ("logc", "scene"), ("fitted", "scene"))])
"""(tone mapper, size, shaper, lattice, output encoding) of the LUTs in the accuracy table. ``logc_hdr``: the
former default bake (LogC to 58.86 on 27 of 32 intervals, a tail to 65504 on the last 5; lut_lattices.py compares
the default, ``logc_extended``). LogC: the default
domain (up to linear 58.86), the full range (up to the sanitize bound 65504, ``domain=FULL_LOGC``) or the scene's
range (``bake_lut(scene=image)``); fitted: the shaper fitted to the
look alone (default) or to the scene, from black to 65504."""


FULL_LOGC = (tg.lut.shapers.LOGC_BLACK, float(tg.color.linear_to_logc(torch.tensor(65504.0, dtype=torch.float64))))
"""A LogC lattice from black to 65504 (LogC ≈ 1.744): no channel is clamped, at 1.8 times the default's spacing."""

LATTICE_TOP = 58.86
"""Linear top of the ``"logc"`` lattice (where ``"logc_hdr"``'s tail starts): the accuracy table also reports the max error on pixels with a channel above it."""


def lattice_domain(domain: str, image: torch.Tensor):
    """``bake_lut``'s ``(scene, domain)`` arguments for a lattice name of :data:`ACCURACY_LUTS`."""
    return (image if domain == "scene" else None), (FULL_LOGC if domain == "full" else None)


def accuracy() -> list:
    """Errors of the LUTs of :data:`ACCURACY_LUTS` on the sample EXRs, in 8-bit sRGB code values, with each bake's own report."""
    looks = {tonemap: strong_look(tonemap=tonemap) for tonemap in ("aces", "neutral")}
    rows = []
    with torch.no_grad():
        for name in ACCURACY_IMAGES:
            image = accuracy_image(name)
            direct = {tonemap: srgb_codes(look(image.double())) for tonemap, look in looks.items()}
            above = (image.amax(1, keepdim=True) > LATTICE_TOP).expand_as(image)
            for tonemap, size, shaper, domain, encoding in ACCURACY_LUTS:
                scene, lattice = lattice_domain(domain, image)
                lut = tg.bake_lut(looks[tonemap], size=size, shaper=shaper, scene=scene, domain=lattice,
                                  output_encoding=encoding, report_tolerance=float("inf"))  # the report's numbers, without its diagnosis
                for interpolation in INTERPOLATIONS:
                    error = (srgb_codes(lut(image, interpolation)) - direct[tonemap]).abs()
                    above_top = float(error[above].max()) if bool(above.any()) else 0.0
                    error = error.flatten().numpy()
                    rows.append({"image": name, "tonemap": tonemap, "size": size, "shaper": shaper, "domain": domain,
                                 "output_encoding": encoding, "interpolation": interpolation,
                                 "p99_9": float(np.quantile(error, 0.999)), "max": float(error.max()), "max_above_top": above_top,
                                 "report_p99_9": lut.error_report.p99_9, "report_max": lut.error_report.max})
    return rows


def temporary_bytes_per_pixel(run, output_bytes: int, pixels: int):
    """Peak resident memory during ``run()`` beyond what was resident before and its output, per pixel."""
    peak_mb = peak_rss_mb(run)
    return None if peak_mb is None else max(0.0, (peak_mb * 2**20 - output_bytes) / pixels)


def lookup_methods(image: torch.Tensor, lut, folder: str) -> dict:
    """Every way of applying ``lut`` to ``image``, as timer calls ``run`` or ``(run, reset)`` by name (the copy first)."""
    compiled = tg.LUT3D(lut.table, shaper="linear", compile=True)
    path = os.path.join(folder, "bench.cube")
    tg.io.write_cube(path, lut)
    methods = {
        "plain tensor copy (memory floor)": lambda: image.clone(),
        "grid_sample 5-D, naive": lambda: trilinear_grid_sample(image.clamp(0, 1), lut.table),
    }
    for interpolation in ("tetrahedral", "trilinear"):
        methods[f"torchgrade {interpolation}, eager (default)"] = lambda mode=interpolation: lut(image, mode)
        methods[f"torchgrade {interpolation}, compile=True"] = lambda mode=interpolation: compiled(image, mode)
    for interpolation in ("tetrahedral", "trilinear"):
        processor = ocio_processor(path, interpolation)
        methods[f"OpenColorIO CPU processor, {interpolation} (in place)"] = ocio_in_place(processor, image)
    return methods


def warm_up(methods: dict) -> dict:
    """Run every method once (the compiled paths compile here); returns the compile paths' first-call seconds."""
    compile_s = {}
    for name, call in methods.items():
        run, reset = run_and_reset(call)
        if reset:
            reset()
        start = time.perf_counter()
        with torch.no_grad():
            run()
        if "compile=True" in name:
            compile_s[name] = time.perf_counter() - start
    return compile_s


def memory_per_pixel(methods: dict, frame_bytes: int, pixels: int) -> dict:
    """:func:`temporary_bytes_per_pixel` of every method, with every large buffer a fresh mapping (slows allocation)."""
    map_large_buffers()
    memory = {}
    for name, call in methods.items():
        run, reset = run_and_reset(call)
        if reset:
            reset()
        output_bytes = 0 if name.startswith("OpenColorIO") else frame_bytes  # OpenColorIO writes in place
        with torch.no_grad():
            memory[name] = temporary_bytes_per_pixel(run, output_bytes, pixels)
    return memory


def speed_rows(methods: dict, compile_s: dict, memory: dict, pixels: int) -> list:
    """Medians of interleaved rounds, with ratios to OpenColorIO's tetrahedral processor and to the copy."""
    medians = median_ms(methods, RUNS, warmup=0)  # warmed up by :func:`warm_up`
    ocio = next(ms for name, ms in medians.items() if name.startswith("OpenColorIO CPU processor, tetrahedral"))
    copy = next(iter(medians.values()))
    results = []
    for name, ms in medians.items():
        result = {"method": name, "ms": ms, "temporary_bytes_per_pixel": memory[name]}
        if name in compile_s:
            result["compile_s"] = compile_s[name]
        result.update(ms_per_megapixel=ms / (pixels / 1e6), ratio_to_ocio_tetrahedral=ms / ocio, ratio_to_copy=ms / copy)
        results.append(result)
    return results


def main(argv=None) -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--memory", action="store_true", help="measure memory only and print it (the child process)")
    args = parser.parse_args(argv)
    import PyOpenColorIO as OCIO

    measure_memory = args.memory
    if not measure_memory:  # time cold compiles: a fresh inductor cache, which the memory child then reuses
        inductor_cache = tempfile.TemporaryDirectory()
        os.environ["TORCHINDUCTOR_CACHE_DIR"] = inductor_cache.name

    torch.manual_seed(0)
    image = torch.rand(1, 3, HEIGHT, WIDTH) * 1.1 - 0.05
    pixels, frame_bytes = HEIGHT * WIDTH, image.numel() * 4
    lut = tg.bake_lut(look, size=SIZE, shaper="linear", report_tolerance=float("inf"))
    lut.table = lut.table.float()
    with tempfile.TemporaryDirectory() as folder:
        methods = lookup_methods(image, lut, folder)
    compile_s = warm_up(methods)
    if measure_memory:  # child process: memory only, away from the timings
        print(json.dumps(memory_per_pixel(methods, frame_bytes, pixels)))
        return
    child = subprocess.run([sys.executable, __file__, "--memory"], capture_output=True, text=True, check=True)
    memory = json.loads(child.stdout.strip().splitlines()[-1])
    load = os.getloadavg()[0]
    speed = speed_rows(methods, compile_s, memory, pixels)
    load = (load, os.getloadavg()[0])  # 1-minute load average before and after the timed rounds
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
        "load_average": load,
        "results": speed,
        "accuracy": accuracy() if EXR_DIR.is_dir() else [],
    }
    write_results(args.out, "lut", report, markdown(report).splitlines(), COMMAND)


def markdown(report: dict) -> str:
    lines = [
        f"# Applying a {report['lut']} LUT to {report['frame']} on CPU",
        "",
        f"Median of {report['runs']} round-robin rounds, {report['threads']} threads, torch {report['torch']}, "
        f"OpenColorIO {report['opencolorio']}. {report['note'].capitalize()} (1-minute load average "
        f"{report['load_average'][0]:.2f} before the timing, {report['load_average'][1]:.2f} after, on {report['cpu_count']} CPUs).",
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
            "## Accuracy of LUTs of a strong look (every 4th pixel, 8-bit sRGB code values vs direct float64)",
            "",
            "Look: contrast 30, saturation 20, temperature 20, then ACES, or post-exposure 0.5 and Neutral. logc_hdr: "
            "the former default (LogC to 58.86 on 27 of 32 intervals, then 4 intervals to LogC 1.3 ≈ 997 and 1 to 65504; the default, `logc_extended` 51³, is compared in lut_lattices.md). "
            "LogC lattice: the default (up to linear 58.86), the full range (black to 65504, `domain=(LOGC_BLACK, 1.744)`), or the scene's "
            "range (`bake_lut(scene=image)`); fitted: "
            "`shaper=\"fitted\"`, fitted to the look (default) or to the image (scene: tables with fitted entries steer its planes; the rows here sample the entries), black to 65504. "
            "Report: the bake's own `error_report` (validation colours, plus the image's pixels for scene bakes). "
            "Max > 58.86: the max error on pixels with a channel above the LogC lattice's top (Desk 1583 of them, "
            "CandleGlass 27, GoldenGate 2).",
            "",
            "| image | look | size | shaper | lattice | output encoding | interpolation | p99.9 | max | max > 58.86 | report p99.9 | report max |",
            "| --- | --- | ---: | --- | --- | --- | --- | ---: | ---: | ---: | ---: | ---: |",
        ]
        for a in report["accuracy"]:
            lines.append(f"| {a['image']} | {a['tonemap']} | {a['size']}³ | {a['shaper']} | {a['domain']} | {a['output_encoding']} | "
                         f"{a['interpolation']} | {a['p99_9']:.2f} | {a['max']:.1f} | {a['max_above_top']:.1f} | {a['report_p99_9']:.2f} | {a['report_max']:.1f} |")
    lines += ["", f"Reproduce: `{report['command']}`", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
