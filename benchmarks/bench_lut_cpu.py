"""The eager 33³ tetrahedral LUT lookup against OpenColorIO's CPU processor at 1920x1080, on 1, 2 and all cores, on a
quiet machine and with a second process loading every core.

For each core count the rounds alternate, each running every method once on the same frame (float32, planar for
torchgrade, packed RGB for OpenColorIO, the same .cube table): torchgrade's ``LUT3D`` as it runs by default (the
operator ``torchgrade::lut_lookup``, whose CPU kernel is the C loop of ``torchgrade/lut/lookup.c`` built with the
package, on that many of torch's threads), the same with the built loop taken away (the torch form an install
built without a C compiler runs), and OpenColorIO two ways: one ``applyRGB`` call on the
whole frame (what its CPU processor does with a frame: one thread), and the frame in 64 row strips spread over that
many threads (its best here: a strip's buffers stay in cache, and its Python binding lets go of the GIL). The load is a
child process multiplying 512x512 matrices on every core for the whole loaded part. The loaded part runs twice: in this
process, and in a child process started with ``OMP_WAIT_POLICY=passive`` (the load keeps the default), because
torchgrade's C loop runs on torch's OpenMP threads, which by default spin a while at the end of each parallel
region, and on a loaded machine a spinning thread holds a core that a thread with work is waiting for. Each ratio is the median over
rounds of torchgrade's time over OpenColorIO's in the same round. Two frames: uniform noise in [-0.05, 1.05] (every
pixel in a different cell: the worst case for caches) and the demo scene (smooth, like footage).

First use: a fresh process times its first and second lookups (nothing is compiled at run time: the loop came built
with the package).

Run: ``.venv/bin/python -m benchmarks lut_cpu [--rounds N] [--out DIR]`` (writes lut_cpu.json and lut_cpu.md;
the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

import torchgrade as tg
from benchmarks.bench_lut import look
from benchmarks.common import argument_parser, ocio_processor, packed_rgb, write_results
from torchgrade.lut import operator

COMMAND = ".venv/bin/python -m benchmarks lut_cpu"
HEIGHT, WIDTH, SIZE, STRIPS = 1080, 1920, 33, 64
LOAD = """
import sys, torch
torch.set_num_threads(int(sys.argv[1]))
a = torch.rand(512, 512)
while True:
    a = (a @ a).clamp_(0, 1)
"""

FIRST_USE = """
import time
import torch, torchgrade as tg
from torchgrade.lut import operator
lut = tg.LUT3D(torch.rand(33, 33, 33, 3))
image = torch.rand(1, 3, 64, 64)
with torch.no_grad():
    t0 = time.perf_counter(); lut(image); first = time.perf_counter() - t0
    t0 = time.perf_counter(); lut(image); second = time.perf_counter() - t0
print(first, second, operator.NATIVE is not None)
"""


def frames() -> dict:
    """The two frames, ``(1, 3, H, W)`` float32."""
    noise = torch.rand(1, 3, HEIGHT, WIDTH, generator=torch.Generator().manual_seed(0)) * 1.1 - 0.05
    return {"noise": noise, "demo scene": tg.scene.demo_scene(HEIGHT, WIDTH).clamp(0, 1.05)}


def methods(image: torch.Tensor, lut: tg.LUT3D, processor, threads: int) -> dict:
    """Every method on ``image`` as ``(run, reset)`` timer calls by name; OpenColorIO's work in place on a buffer that
    ``reset`` restores (untimed)."""
    source = packed_rgb(image)
    buffer = source.copy()
    strips = np.array_split(buffer, STRIPS, axis=0)
    pool = ThreadPoolExecutor(threads) if threads > 1 else None

    def torch_only():
        native, operator.NATIVE = operator.NATIVE, None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # the torch form's: built without a compiler
                lut(image)
        finally:
            operator.NATIVE = native

    def in_strips():
        if pool is None:
            for strip in strips:
                processor.applyRGB(strip)
        else:
            list(pool.map(processor.applyRGB, strips))

    reset = lambda: np.copyto(buffer, source)  # noqa: E731
    return {
        "torchgrade (default)": (lambda: lut(image), None),
        "torchgrade, torch form (no C compiler)": (torch_only, None),
        "OpenColorIO, one applyRGB call": (lambda: processor.applyRGB(buffer), reset),
        f"OpenColorIO, {STRIPS} strips on the threads": (in_strips, reset),
    }


def timed_rounds(calls: dict, rounds: int) -> dict:
    """``{name: [ms per round]}``, every round running each call once, starting one call later each round."""
    names = list(calls)
    times = {name: [] for name in names}
    with torch.no_grad():
        for attempt in range(rounds + 1):  # the first round warms up
            order = names[attempt % len(names):] + names[:attempt % len(names)]
            for name in order:
                run, reset = calls[name]
                if reset:
                    reset()
                start = time.perf_counter()
                run()
                if attempt:
                    times[name].append((time.perf_counter() - start) * 1e3)
    return times


def measure(rounds: int, loaded: bool, lut, processor) -> list:
    """Rows for every frame and core count, with the load process running when ``loaded`` (OpenMP's default wait
    policy, whatever this process was given)."""
    cores = os.cpu_count() or 1
    environment = {name: value for name, value in os.environ.items() if name != "OMP_WAIT_POLICY"}
    load = subprocess.Popen([sys.executable, "-c", LOAD, str(cores)], env=environment) if loaded else None
    try:
        time.sleep(2.0 if loaded else 0.0)
        rows = []
        for frame_name, image in frames().items():
            for threads in sorted({1, 2, cores}):
                torch.set_num_threads(threads)
                times = timed_rounds(methods(image, lut, processor, threads), rounds)
                rows.append(_row(frame_name, threads, loaded, times))
        return rows
    finally:
        if load is not None:
            load.kill()
            load.wait()


def _row(frame: str, threads: int, loaded: bool, times: dict) -> dict:
    names = list(times)
    ours, torch_form, whole, strips = names
    ratio = lambda a, b: statistics.median(x / y for x, y in zip(times[a], times[b]))  # noqa: E731
    return {"frame": frame, "threads": threads, "loaded": loaded, "wait_policy": os.environ.get("OMP_WAIT_POLICY", "default"),
            "ms": {name: statistics.median(values) for name, values in times.items()},
            "ratio_to_ocio_whole": ratio(ours, whole), "ratio_to_ocio_strips": ratio(ours, strips),
            "torch_form_ratio_to_ocio_strips": ratio(torch_form, strips)}


def passive_rows(rounds: int) -> list:
    """The loaded rows measured in a child process whose OpenMP threads wait passively."""
    environment = {**os.environ, "OMP_WAIT_POLICY": "passive"}
    done = subprocess.run([sys.executable, "-m", "benchmarks.bench_lut_cpu", "--loaded-only", "--rounds", str(rounds)],
                          env=environment, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def first_use() -> dict:
    """Seconds of the first and second lookup in a fresh process, and whether the built loop ran."""
    done = subprocess.run([sys.executable, "-c", FIRST_USE], capture_output=True, text=True, check=True)
    first, second, native = done.stdout.split()
    return {"fresh process": {"first_s": float(first), "second_s": float(second), "compiled_loop": native == "True"}}


QUICK = "3 rounds instead of 15"
"""What ``--quick`` leaves out."""


def main(argv=None) -> None:
    parser = argument_parser(__doc__, QUICK)
    parser.add_argument("--rounds", type=int, help="alternating rounds (default 15, or 3 with --quick)")
    parser.add_argument("--loaded-only", action="store_true", help="print the loaded rows as JSON (the passive child)")
    args = parser.parse_args(argv)
    if args.rounds is None:
        args.rounds = 3 if args.quick else 15
    import PyOpenColorIO as OCIO

    lut = tg.bake_lut(look, size=SIZE, shaper="linear", report_tolerance=float("inf"))
    lut.table = lut.table.float()
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "bench.cube")
        tg.io.write_cube(path, lut)
        processor = ocio_processor(path, "tetrahedral")
    if args.loaded_only:
        print(json.dumps(measure(args.rounds, True, lut, processor)))
        return
    threads = torch.get_num_threads()
    rows = measure(args.rounds, False, lut, processor) + measure(args.rounds, True, lut, processor) + passive_rows(args.rounds)
    torch.set_num_threads(threads)
    report = {"command": COMMAND, "frame": f"{WIDTH}x{HEIGHT} float32", "lut": f"{SIZE}^3 tetrahedral, linear shaper",
              "rounds": args.rounds, "cpu_count": os.cpu_count(), "torch": torch.__version__, "opencolorio": OCIO.__version__,
              "cpu_capability": torch.backends.cpu.get_cpu_capability(), "rows": rows, "first_use": first_use()}
    write_results(args.out, "lut_cpu", report, markdown(report).splitlines(), COMMAND)


def markdown(report: dict) -> str:
    lines = [f"# The eager {report['lut']} lookup against OpenColorIO at {report['frame']}, on 1, 2 and all cores", "",
             f"Median of {report['rounds']} alternating rounds per row; {report['cpu_count']} CPUs (torch's capability "
             f"{report['cpu_capability']}), torch {report['torch']}, OpenColorIO {report['opencolorio']}. Loaded: a second "
             "process multiplying matrices on every core; \"passive\": this process's OpenMP threads wait passively "
             "(`OMP_WAIT_POLICY=passive`). Ratios: the median over rounds of torchgrade's time over "
             "OpenColorIO's in the same round (below 1: torchgrade is faster).", "",
             "| frame | cores | load | torchgrade ms | torch form ms | OCIO one call ms | OCIO strips ms | × OCIO one call | "
             "× OCIO strips | torch form × OCIO strips |",
             "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in report["rows"]:
        ms = list(r["ms"].values())
        load = ("loaded, passive" if r["wait_policy"] == "passive" else "loaded") if r["loaded"] else "quiet"
        lines.append(f"| {r['frame']} | {r['threads']} | {load} | {ms[0]:.1f} | {ms[1]:.1f} | "
                     f"{ms[2]:.1f} | {ms[3]:.1f} | {r['ratio_to_ocio_whole']:.2f} | {r['ratio_to_ocio_strips']:.2f} | "
                     f"{r['torch_form_ratio_to_ocio_strips']:.2f} |")
    lines += ["", "First use (a fresh process, a 33³ LUT on a 64x64 frame):", "",
              "| process | first lookup s | second lookup s | C loop |", "| --- | ---: | ---: | --- |"]
    for case, r in report["first_use"].items():
        lines.append(f"| {case} | {r['first_s']:.3f} | {r['second_s']:.4f} | {'yes' if r['compiled_loop'] else 'no'} |")
    lines += ["", f"Reproduce: `{report['command']}`", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
