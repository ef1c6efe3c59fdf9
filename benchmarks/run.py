"""The benchmark suite: every way torchgrade (and its peers) can compute one strong look, for speed and accuracy.

    .venv/bin/python -m benchmarks suite [--quick] [--device cpu|cuda] [--out DIR]
    .venv/bin/python -m benchmarks suite --committed     # both forms into benchmarks/results/suite, then the pages
    .venv/bin/python -m benchmarks suite --pages         # only the pages, from the committed results

Writes to ``--out`` (default ``benchmarks/out``, git-ignored). The committed results are the quick form's in
``benchmarks/results/suite/quick`` and the full form's in ``benchmarks/results/suite/full``; ``--committed`` makes
both, each in a fresh process, and then writes every figure the pages quote from them
(:mod:`benchmarks.suite.pages`: the marked blocks of ``docs/performance.md`` and ``README.md``).
``tests/project/test_suite_results.py`` re-derives the quick form's accuracy columns from the code and holds the
pages to the results.

**The look** (:data:`benchmarks.suite.workload.LOOK`): eye adaptation (every frame a first frame), scattering bloom,
an ACES-space grade (exposure, temperature, contrast, saturation, split toning) and the ACES tone mapper. Eye
adaptation meters the frame and bloom looks at neighbouring pixels, so both run live; the *per-pixel stage* (grade +
tone map) is what most rows compute in different ways, and *whole-look* rows compute all of it.

**Rows** (:func:`benchmarks.suite.methods.method_rows`): the per-pixel stage computed directly in float32, bfloat16
and float16 (the library computes half inputs in float32: those rows measure the conversion and the quantisation of
half inputs); the default bake (``tg.bake_lut`` with every default: its size and lattice are read from the LUT it
returns) looked up tetrahedrally in both CPU forms (the C loop built with the package and the torch form,
:mod:`benchmarks.suite.forms`) and trilinearly by the loop; a 33³ LogC LUT, the twin of OpenColorIO's row;
``look.to_lut()`` (the baked look: eye adaptation and bloom live, the default bake after them); the default bake
exported to ONNX and run by onnxruntime and by OpenVINO (f32); OpenColorIO's CPU processor on the 33³ LogC LUT as a
``.cube`` and on the default bake as CLF. Whole-look rows: direct float32, the baked look, and the exported look on
both runtimes. The full run adds the float64 reference itself, trilinear's torch form, ``torch.compile``
(``tg.compile`` of the direct stage and of the whole look, ``LUT3D(compile=True)`` of the default bake; a row whose
compilation fails records why), the exported per-pixel stage and baked look, OpenVINO's default precision, every LUT
size (9, 17, 33, 65) × lattice × interpolation with OpenColorIO at each (``.cube`` lattices) and 33³ and 65³ LogC
LUTs whose lattice reaches the scenes' brightest pixel (``bake_lut(scene=...)``). Linear-shaper LUTs clip above 1:
the table keeps them, the plot leaves them out.

**Accuracy** is measured on the whole look: the scene goes through the live stages (in the row's dtype) and the
row's per-pixel stage, and is compared with the float64 look, on the sample photographs (Desk, CandleGlass,
GoldenGate, Carrots, Garden), BrightRings and the procedural demo scene, pooled: max and 99.9th percentile absolute
error in 8-bit sRGB code values over every channel of every pixel, and mean ΔE2000 over a fixed random sample of
pixels (see :mod:`benchmarks.metrics`). ``--quick`` measures on images area-downscaled to at most
:data:`~benchmarks.suite.workload.QUICK_SIDE` pixels a side. Accuracy is deterministic: nothing in it is timed.

**Speed** is the timed part of each row (its ``timed`` field: the per-pixel stage, or the whole look) on the demo
scene rendered at 1920×1080 (through the live stages first for per-pixel rows). Every row and baseline is timed in
one session, alternated (each round runs each once, after a warm-up round), so a change of load hits them all
alike: median ms per megapixel, and ratios to a plain copy of the frame (the memory floor) and to OpenColorIO's 33³
LogC tetrahedral processor as medians of each round's ratio. The report checks the eager whole look against its
parts timed in the same rounds; ``results.json`` keeps every round's ms (``rounds_ms``). OpenColorIO is timed on its
in-place apply (the buffer is restored between runs, untimed); onnxruntime and OpenVINO on ``run`` with the image
already in a numpy array (onnxruntime: ``intra_op_num_threads`` = CPU count). The live stages, the part every look
pays on top of a per-pixel row, are timed on their own (``baselines``).

**Peak memory** (full run) is what the timed part adds to the process at 1920×1080, its output included, after
every timing is done: CPU peak resident memory with every buffer above 64 KiB given its own mapping
(:func:`benchmarks.common.map_large_buffers`) and onnxruntime's arena switched off; CUDA peak allocated memory on a GPU.

**Scaling**: the direct float32 stage and the default bake's tetrahedral lookup from 256² to 3840×2160 (up to 1024²
under ``--quick``) and at batch sizes 1, 2, 4, 8 of 512².

**Report**: one line of advice per use (training, serving, baking a LUT) computed from the run's numbers, the
warnings the run raised (e.g. ``LUTAccuracyWarning``), collected instead of printed, the commit measured (with
whether its code had uncommitted changes), the command, wall and CPU seconds. The terminal gets a short table.

Writes ``results.json``, ``results.md``, ``pareto.png`` and ``scaling.png`` to ``--out``. The parts live in
``benchmarks/suite/``: ``workload`` (look, scenes, reference), ``rows``, ``methods`` and ``runtimes`` (the rows),
``forms`` (the CPU lookup forms), ``measure`` (accuracy, speed, memory, scaling), ``report`` (markdown, plots),
``stamp`` (commit, CPU time) and ``pages`` (the figures the docs quote).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import torch

from benchmarks import common
from benchmarks.suite import measure, pages, report, stamp
from benchmarks.suite.workload import FRAME, LOOK, Plan, Workload


def measure_everything(work: Workload) -> dict:
    """Every measurement of the run, as the report's fields."""
    methods, records = measure.measure_rows(work)
    times = measure.time_rows(work, methods)
    base = measure.add_speed(records, times)
    points = measure.scaling(work)
    if work.plan.peak_memory:
        measure.record_peak_memory(work, methods, records)
    return {"baselines": base, "rows": records, "scaling": points, "check": measure.whole_look_check(times),
            "advice": report.advice(records, base), "rounds_ms": {name: [round(ms, 2) for ms in t] for name, t in times.items()}}


QUICK = "the rows a choice hangs on, smaller accuracy images, fewer rounds, scaling up to 1024², no torch.compile, no peak memory"
"""What ``--quick`` leaves out."""


def run_suite(plan: Plan) -> dict:
    """One run of ``plan``: measures, writes its results to ``plan.out`` and returns them."""
    started, cpu_started, source = time.perf_counter(), stamp.cpu_seconds(), stamp.source_commit()  # the code loaded now
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory(prefix="torchgrade-bench-") as folder, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # into the report, not between the progress bars
        work = Workload(plan, Path(folder))
        measured = measure_everything(work)
    results = {
        "command": plan.command(), **source, "quick": plan.quick, "device": plan.device.type, "look": LOOK,
        "frame": list(FRAME), "runs": plan.runs, "statistic": "median, ratios: median of each round's ratio",
        "scenes": list(work.scenes), "accuracy_sizes": {name: list(image.shape[-2:]) for name, image in work.scenes.items()},
        "delta_e_samples": int(work.delta_e_pixels.numel()), **measured,
        "warnings": report.warning_records(caught), "wall_s": time.perf_counter() - started,
        "cpu_s": stamp.cpu_seconds() - cpu_started,
    }
    common.write_results(plan.out, "results", results, report.markdown(results), plan.command(), plan.device.type, announce=False)
    report.plot_pareto(results["rows"], plan.out / "pareto.png")
    report.plot_scaling(results["scaling"], plan.out / "scaling.png")
    return results


def run_committed() -> int:
    """The quick and the full form into the committed results, each in a fresh process, then the pages."""
    for form, folder in pages.COMMITTED.items():
        command = [sys.executable, "-m", "benchmarks", "suite", *(["--quick"] if form == "quick" else []), "--out", str(folder)]
        if subprocess.run(command, cwd=common.ROOT).returncode:
            return 1
    return pages.main()


def main(argv=None) -> int:
    parser = common.argument_parser(__doc__, QUICK)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--committed", action="store_true", help="run both forms into benchmarks/results/suite, then write the pages")
    parser.add_argument("--pages", action="store_true", help="only write the pages' figures from the committed results")
    args = parser.parse_args(argv)
    if args.pages or args.committed:
        return pages.main() if args.pages else run_committed()
    plan = Plan.of(args.quick, args.device, args.out)
    results = run_suite(plan)
    print(report.short_table(results))
    print(f"\nwrote {plan.out / 'results'}.json and .md, pareto.png, scaling.png; reproduce: {plan.command()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
