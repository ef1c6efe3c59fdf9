"""The eager CPU paths on this machine's threads: the cinematic look, its stages, ACES 2.0 and 33³ LUTs at 1920x1080,
``RandomPostFX`` on a 32x3x224x224 batch and the look's training step (forward and backward) on 4x3x256x384; with
``--compiled``, the look, its per-pixel stages, ``RandomPostFX`` and the training step through ``tg.compile`` (each
compiles in the first, untimed round). ``--cases`` times only the cases named.

    python benchmarks/bench_cpu_paths.py [--runs N] [--threads N] [--clock wall|cpu] [--compiled]
        [--cases NAME ...] [--json FILE]

Prints the median ms of each case (every round runs each case once: A B C A B C ...). It uses only the public API, so
two versions of torchgrade can be compared by running it under each (``PYTHONPATH=<checkout>``) in turn; the
closing comparison of a change quotes the medians of such alternating runs. ``--json`` also writes them to FILE.
``--clock cpu`` times the process's CPU seconds instead of the wall clock: on a shared machine, where other work
takes the cores, it measures the work of a change rather than the neighbours' (with ``--threads 1``, no thread
waits at a barrier either).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import torch

import torchgrade as tg

ROOT = Path(__file__).resolve().parents[1]
CINEMATIC = json.loads((ROOT / "export" / "looks" / "cinematic.json").read_text())


COMPILED = ("cinematic look", "grade", "tone map aces", "tone map aces2", "RandomPostFX 32x224^2", "cinematic training 4x256x384")
"""The cases ``--compiled`` times, each module through ``tg.compile``."""


def training_step(look, batch: torch.Tensor):
    """One forward and backward of ``look`` on a copy of ``batch`` that requires grad (gradients on, whatever the caller's
    mode)."""
    def step():
        with torch.enable_grad():
            image = batch.clone().requires_grad_()
            look(image).mean().backward()
    return step


def cases(compiled: bool = False) -> dict:
    """Every case: a call on a 1920x1080 frame (or a batch), its inputs made once; ``compiled``: the :data:`COMPILED`
    ones, through ``tg.compile``."""
    image = tg.scene.demo_scene(1080, 1920)
    look = tg.PostFX.from_config(CINEMATIC).eval()
    grade = tg.ColorGrade(**CINEMATIC["grade"])
    tonemap = tg.ToneMap("aces")
    bloom = tg.Bloom(**CINEMATIC["bloom"])
    exposure = tg.AutoExposure(**CINEMATIC["exposure"])  # no dt: every frame meters afresh
    lut = tg.bake_lut(tg.PostFX(grade={"contrast": 20, "saturation": 10}, tonemap="aces"), size=33, report_tolerance=float("inf"))
    pixels = torch.rand(1, 3, 1080, 1920, generator=torch.Generator().manual_seed(0)) * 1.1 - 0.05
    aces2 = tg.ToneMap("aces2")
    hdr_lut = tg.LUT3D(torch.rand(33, 33, 33, 3, generator=torch.Generator().manual_seed(1)), shaper="logc_hdr")
    augment = tg.RandomPostFX(contrast=30, saturation=30, hue_shift=20, post_exposure=0.5, input_space="srgb")
    batch = torch.rand(32, 3, 224, 224, generator=torch.Generator().manual_seed(2))
    training_batch = torch.rand(4, 3, 256, 384, generator=torch.Generator().manual_seed(3)) * 4
    trained = tg.PostFX.from_config(CINEMATIC).eval()
    if compiled:
        look, grade, tonemap, aces2, augment = (tg.compile(module) for module in (look, grade, tonemap, aces2, augment))
        trained = tg.compile(trained, dynamic=False)  # its own sizes, fixed, as the look's frame is (a class compiles apart)
    calls = {
        "cinematic look": lambda: look(image),
        "grade": lambda: grade(image),
        "tone map aces": lambda: tonemap(image),
        "tone map aces2": lambda: aces2(image),
        "bloom scattering": lambda: bloom(image),
        "exposure histogram": lambda: exposure(image),
        "LUT 33^3 tetrahedral": lambda: lut(pixels, "tetrahedral"),
        "LUT 33^3 logc_hdr": lambda: hdr_lut(image),
        "RandomPostFX 32x224^2": lambda: augment(batch),
        "cinematic training 4x256x384": training_step(trained, training_batch),
    }
    return {name: calls[name] for name in COMPILED} if compiled else calls


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's)")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    parser.add_argument("--compiled", action="store_true", help="the look, its per-pixel stages, RandomPostFX and the training step through tg.compile")
    parser.add_argument("--cases", nargs="+", metavar="NAME", help="only these cases (default: every one)")
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    clock = time.perf_counter if args.clock == "wall" else time.process_time
    calls = cases(args.compiled)
    unknown = set(args.cases or ()) - set(calls)
    if unknown:
        parser.error(f"unknown case(s) {sorted(unknown)}; the cases: {', '.join(calls)}")
    calls = {name: call for name, call in calls.items() if not args.cases or name in args.cases}
    times = {name: [] for name in calls}
    with torch.no_grad():
        for attempt in range(args.runs + 1):
            for name, call in calls.items():
                start = clock()
                call()
                if attempt:  # the first round warms up
                    times[name].append((clock() - start) * 1e3)
    medians = {name: round(statistics.median(values), 2) for name, values in times.items()}
    print(json.dumps({"threads": torch.get_num_threads(), "clock": args.clock, "compiled": args.compiled,
                      "torchgrade": str(Path(tg.__file__).parent),
                      "ms": medians}))
    if args.json:
        args.json.write_text(json.dumps(medians, indent=2) + "\n")


if __name__ == "__main__":
    main()
