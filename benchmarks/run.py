"""The benchmark suite: every way torchgrade (and its peers) can compute one strong look, for speed and accuracy.

    .venv/bin/python -m benchmarks suite [--quick] [--device cpu|cuda] [--out DIR]

Writes to ``--out`` (default ``benchmarks/out``, git-ignored; the committed results are
``--out benchmarks/results/suite``).

**The look** (:data:`benchmarks.suite.workload.LOOK`): scattering bloom, an ACES-space grade (exposure, temperature, contrast,
saturation, split toning) and the ACES tone mapper. Bloom looks at neighbouring pixels, so it always
runs live; the *per-pixel stage* (grade + tone map) is what the methods compute in different ways.

**Rows** (:func:`benchmarks.suite.methods.method_rows`): the per-pixel stage computed directly in float64 (the reference),
float32, bfloat16 and float16 (the library computes half inputs in float32: those rows measure the
conversion and the quantisation of half inputs); baked into LUTs of 9, 17, 33 and 65 points per axis,
linear, LogC or the default lattice (``logc_hdr``: what ``PostFX.to_lut`` and ``bake_lut`` give an HDR look)
shaper, trilinear or tetrahedral lookup (plus 33³ and 65³ LogC LUTs whose lattice reaches the scenes'
brightest pixel, ``bake_lut(scene=...)``, instead of LogC 1.0 ≈ 58.9); ``torch.compile``d (full run only;
a row whose compilation fails records why); exported to ONNX and run by onnxruntime; and the same LUTs
written as .cube files and applied by OpenColorIO's CPU processor. Two *whole-look* rows (bloom included)
compare PyTorch and onnxruntime on the exported look. Linear-shaper LUTs clip above 1: the table keeps
them, the plot leaves them out. ``--quick`` keeps the LUT rows a choice hangs on (33³ and 65³, LogC and
the default lattice; OpenColorIO at 33³; onnxruntime tetrahedral only) and measures no peak memory.

**Accuracy** is measured on the whole look: the scene goes through bloom (in the row's dtype) and the
row's per-pixel stage, and is compared with the float64 look, on the sample EXRs (Desk, CandleGlass,
GoldenGate, BrightRings) and the procedural demo scene, pooled: max and 99.9th percentile absolute
error in 8-bit sRGB code values over every channel of every pixel, and mean ΔE2000 over a fixed random
sample of pixels (see :mod:`benchmarks.metrics`). ``--quick`` measures on images area-downscaled to
at most 400 pixels a side.

**Speed** is the timed part of each row (its ``timed`` field: the per-pixel stage, or the whole look)
on the demo scene rendered at 1920×1080 (bloomed first for per-pixel rows). Every row and baseline is
timed in one session, alternated (each round runs each once, after a warm-up round), so a change of
load hits them all alike: median ms per megapixel, and ratios to a plain copy of the frame (the memory
floor) and to OpenColorIO's 33³ LogC tetrahedral processor as medians of each round's ratio. The
report checks the eager whole look against its parts timed in the same rounds; ``results.json`` keeps every
round's ms (``rounds_ms``). OpenColorIO is
timed on its in-place apply (the buffer is restored between runs, untimed); onnxruntime on
``session.run`` with the image already in a numpy array, ``intra_op_num_threads`` = CPU count.
Bloom, the part every look pays on top of a per-pixel row, is timed on its own (``baselines``).

**Peak memory** is what the timed part adds to the process at 1920×1080, its output included, after
every timing is done: CPU peak resident memory with every buffer above 64 KiB given its own mapping
(:func:`benchmarks.common.map_large_buffers`) and onnxruntime's arena switched off; CUDA peak
allocated memory on a GPU.

**Scaling**: the direct float32 and the 33³ default-lattice tetrahedral LUT per-pixel stages from 256² to
3840×2160 (up to 1024² under ``--quick``) and at batch sizes 1, 2, 4, 8 of 512².

**Report**: one line of advice per use (training, serving, baking a LUT) computed from the run's
numbers, and the warnings the run raised (e.g. ``LUTAccuracyWarning``), collected instead of printed.

Writes ``results.json``, ``results.md``, ``pareto.png`` and ``scaling.png`` to ``--out``. The parts live in
``benchmarks/suite/``: ``workload`` (look, scenes, reference), ``methods`` (the rows), ``measure`` (accuracy,
speed, memory, scaling) and ``report`` (markdown, plots).
"""

from __future__ import annotations

import tempfile
import time
import warnings
from pathlib import Path

import torch


from benchmarks import common
from benchmarks.suite import measure, report
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


def main(argv=None) -> dict:
    parser = common.argument_parser(__doc__, QUICK)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    plan = Plan.from_args(parser.parse_args(argv))
    started = time.perf_counter()
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory(prefix="torchgrade-bench-") as folder, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # into the report, not between the progress bars
        work = Workload(plan, Path(folder))
        measured = measure_everything(work)
    results = {
        "command": plan.command(), "quick": plan.quick, "device": plan.device.type, "look": LOOK,
        "frame": list(FRAME), "runs": plan.runs, "statistic": "median, ratios: median of each round's ratio",
        "scenes": list(work.scenes), "accuracy_sizes": {name: list(image.shape[-2:]) for name, image in work.scenes.items()},
        "delta_e_samples": int(work.delta_e_pixels.numel()), **measured,
        "warnings": report.warning_records(caught), "wall_s": time.perf_counter() - started,
    }
    common.write_results(plan.out, "results", results, report.markdown(results), plan.command(), plan.device.type)
    report.plot_pareto(results["rows"], plan.out / "pareto.png")
    report.plot_scaling(results["scaling"], plan.out / "scaling.png")
    return results


if __name__ == "__main__":
    main()
