"""What the GPU path would cost, counted without a GPU: each case of bench_gpu.py on the ``meta`` device.

    python -m benchmarks gpu_proxy [--out DIR]

For each case it counts the kernel launches an eager forward makes (every operation dispatched, views and allocations aside) and
the bytes they move, in *frame passes* (one pass: a copy of a 4K frame, read and written), with
:class:`torchgrade.testing.dispatch.DispatchCount`. From them it predicts the time on one H200::

    t = sum over launches of max(LAUNCH_MS, PASS_COST * COPY_4K_MS * passes of the launch)

an elementwise kernel runs at the memory's speed, and nothing runs faster than Python and PyTorch dispatch it.
The two constants were fitted (least squares on log time) to the seven eager no_grad rows of
``benchmarks/results/gpu.md`` (run B, the code at ``7319b75``, counted there with this script's counter): every
prediction within 0.84 to 1.13 of its measurement; the training row, outside the fit, is over-predicted 1.30 times.
Against run D (``59fbb9f``, counted as it was) the rows the count sees whole are within 0.87 to 1.03 (grade, ACES, bloom, RandomPostFX),
the 1080p look, bound by its launches, is over-predicted 1.26 times (19 µs a launch there, 24 fitted), and what it
cannot see is a kernel slower than its bytes: atomic additions that wait on each other, or a gather that
takes a block of threads a pixel (``DispatchCount.row_gathers``).
A prediction, not a measurement: a GPU run (``benchmarks/gpu_check.sh``) is what confirms it.

Runs in about a minute on 2 cores. Writes ``gpu_proxy.json`` and ``gpu_proxy.md`` to ``--out`` (default
``benchmarks/out``; the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations


import torch


import torchgrade as tg
from benchmarks.bench_gpu import SIZES, STAGES, augmentations, cinematic
from benchmarks.common import argument_parser, write_results
from torchgrade.testing.dispatch import DispatchCount

LAUNCH_MS = 0.024
"""The least a launch costs eager (Python, PyTorch's dispatch, the driver): fitted, see the module's docstring."""
PASS_COST = 1.055
"""A frame pass of an elementwise kernel over one copy of the frame's time: fitted, see the module's docstring."""
COPY_4K_MS = 0.0546
"""One device-to-device copy of a 3840x2160 float32 RGB frame on an H200 (``benchmarks/results/gpu.md``, run A)."""
MEASURED = {
    "7319b75": {"cinematic 4K": 11.23, "cinematic 1080p": 7.38, "grade": 3.95, "tonemap aces": 4.04, "tonemap aces2": 15.34,
                "bloom scattering": 4.18, "exposure": 0.48, "training 16x512²": 24.90},
    "59fbb9f": {"cinematic 4K": 21.32, "cinematic 1080p": 5.40, "grade": 2.76, "tonemap aces": 3.49, "tonemap aces2": 14.72,
                "bloom scattering": 2.78, "exposure": 13.19, "training 16x512²": 22.01, "RandomPostFX 256x224²": 5.94,
                "kornia ColorJiggle 256x224²": 5.09},
}
"""Eager ms on the H200 of ``benchmarks/results/gpu.md``, by the code measured: runs B and C (``7319b75``: the data of
the fit) and run D (``59fbb9f``)."""
FOUR_K = torch.Size((1, 3) + SIZES["4K"])


def cases() -> dict:
    """``name -> (stage factory, input shape, training)``: bench_gpu's looks, stages, LUT, training step and augmentation
    (kornia's ``ColorJiggle``, its yardstick there, reads values back: it cannot run on ``meta``)."""
    lut = lambda: cinematic().to_lut(33).lut  # noqa: E731
    return {
        "cinematic 4K": (cinematic, FOUR_K, False),
        "cinematic 1080p": (cinematic, (1, 3) + SIZES["1080p"], False),
        **{name: (make, FOUR_K, False) for name, make in STAGES.items()},
        "LUT 33³ tetrahedral": (lut, FOUR_K, False),
        "training 16x512²": (cinematic, (16, 3, 512, 512), True),
        "RandomPostFX 256x224²": (lambda: augmentations()[0], (256, 3, 224, 224), False),
    }


JIGGLE_SHAPE, JIGGLE_COUNTED = (256, 3, 224, 224), 8
"""bench_gpu's batch for ``RandomPostFX`` and kornia's ``ColorJiggle``, and the images of it ``ColorJiggle`` is counted on."""


def counted_colorjiggle() -> DispatchCount:
    """What kornia's ``ColorJiggle`` (``RandomPostFX``'s yardstick in bench_gpu) dispatches on a batch, counted on a
    CPU batch of :data:`JIGGLE_COUNTED` images (it reads values back: it cannot run on ``meta``), its bytes scaled to
    bench_gpu's batch. Its controls are drawn before the count: kornia makes them on the host (bench_gpu leaves the
    layer there), and copies them to a GPU (four small copies, not counted)."""
    jiggle = augmentations()[1]
    batch = torch.rand((JIGGLE_COUNTED,) + JIGGLE_SHAPE[1:])
    count = DispatchCount(frame=torch.empty(FOUR_K, device="meta"))
    with torch.no_grad():
        jiggle(batch)
        params = jiggle.forward_parameters(batch.shape)
        with count:
            jiggle(batch, params=params)
    count.moved = [moved * JIGGLE_SHAPE[0] // JIGGLE_COUNTED for moved in count.moved]
    return count


def counted(make, shape, training: bool) -> DispatchCount:
    """What the second forward (and backward, ``training``) of ``make()`` on ``meta`` dispatches."""
    stage = make().to("meta")
    for _ in range(2):  # the first builds constants and tables
        image = torch.empty(shape, device="meta", requires_grad=training)
        count = DispatchCount(frame=torch.empty(FOUR_K, device="meta"))
        with torch.set_grad_enabled(training), count:
            out = stage(image)
            if training:
                out.mean().backward()
    return count


def predicted_ms(count: DispatchCount) -> float:
    """The module docstring's ``t``, in ms."""
    return sum(max(LAUNCH_MS, PASS_COST * COPY_4K_MS * moved / count.frame_bytes) for moved in count.moved)


def main(argv=None) -> int:
    args = argument_parser(__doc__).parse_args(argv)
    rows = []
    counts = {name: counted(make, shape, training) for name, (make, shape, training) in cases().items()}
    counts["kornia ColorJiggle 256x224²"] = counted_colorjiggle()
    for name, count in counts.items():
        rows.append({"case": name, "launches": count.launches, "frame_passes": round(count.frame_passes, 1), "unvectorised": count.unvectorised,
                     "predicted_ms": round(predicted_ms(count), 2), **{f"measured_ms_{code}": MEASURED[code].get(name) for code in MEASURED}})
        print(rows[-1], flush=True)
    lines = ["# The GPU path, counted on the `meta` device", "",
             f"torch {torch.__version__}, torchgrade {tg.__version__}. Launches and frame passes (bytes moved over one copy "
             "of a 4K frame, read and written) of one eager frame, and the H200 time they predict "
             f"(`max({LAUNCH_MS} ms, {PASS_COST} × {COPY_4K_MS} ms × passes)` summed over launches; see "
             "`benchmarks/gpu_proxy.py`). The last columns are the H200's measurements (`gpu.md`) of the code as it was: at "
             "`7319b75`, the data of the fit, the look metered a log-average and its bloom had no clamp; at `59fbb9f` (run D) "
             "the histogram was counted into one row of bins (13.19 ms at 4K; 1.68 ms per column, run E) and ACES 2.0 gathered "
             "its cusp table a row a pixel (4.99 ms of its 14.72 ms): neither is in the count. kornia's `ColorJiggle` reads values "
             "back and is counted on the CPU instead, on 8 images, scaled to 256, its controls drawn (on the host) "
             "before the count (`counted_colorjiggle`).", "",
             "Unvectorised: the launches among them that CUDA runs in its unvectorised loop (an operand broadcast or strided, "
             "`DispatchCount.unvectorised`); the model charges them as the others.", "",
             "| case | launches | frame passes | unvectorised | predicted H200 ms | " + " | ".join(f"measured at {code}" for code in MEASURED) + " |",
             "| --- | ---: | ---: | ---: | ---: | " + " | ".join("---:" for _ in MEASURED) + " |"]
    for row in rows:
        measured = " | ".join("" if row[f"measured_ms_{code}"] is None else f"{row[f'measured_ms_{code}']:.2f}" for code in MEASURED)
        lines.append(f"| {row['case']} | {row['launches']} | {row['frame_passes']} | {row['unvectorised']} | {row['predicted_ms']:.2f} | {measured} |")
    args.out.mkdir(parents=True, exist_ok=True)
    write_results(args.out, "gpu_proxy", {"rows": rows}, lines, "python -m benchmarks gpu_proxy --out DIR")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
