"""Speed of bloom on CPU, as a ratio to a plain copy of the same frame (the memory floor).

Measures float32 bloom at 1920x1080 in each mode, how the time grows with resolution (512^2 to 4K, odd sides too)
and with ``max_iterations``; each timing is the median (and minimum) of several runs, with the copy
timed alternately with it (:func:`benchmarks.common.interleaved_ms`) so that both see the same machine load. Results go to
``bloom.json`` and ``bloom.md`` in ``--out`` (default benchmarks/out; the committed ones with ``--out benchmarks/results``).

Run from the repository root::

    .venv/bin/python -m benchmarks bloom [--out DIR]
"""

from __future__ import annotations

import platform
import statistics
import sys
import time

import torch


import torchgrade as tg
from benchmarks.common import argument_parser, interleaved_ms, write_results

COMMAND = ".venv/bin/python -m benchmarks bloom"
FULL_HD = (1080, 1920)
RESOLUTIONS = [(512, 512), (333, 517), (1024, 1024), FULL_HD, (1081, 1921), (1440, 2560), (2160, 3840)]
"""Powers of two and the usual video sizes, and odd sides (whose levels are resampled a side at a time)."""
ITERATIONS = [1, 2, 4, 8, 16]
VARIANTS = {
    "additive": {},
    "additive, no firefly fading": {"fade_fireflies": False},
    "scattering": {"mode": "scattering", "intensity": 0.5},
    "scattering, bicubic": {"mode": "scattering", "intensity": 0.5, "bicubic_upsampling": True},
}


def hdr_frame(height: int, width: int) -> torch.Tensor:
    """A frame with light above the threshold everywhere, so the pyramid is always built."""
    generator = torch.Generator().manual_seed(0)
    return torch.rand(1, 3, height, width, generator=generator) * 4.0


def measure(frame: torch.Tensor, repeats: int, **settings) -> dict:
    """Median and minimum milliseconds of bloom and of a copy of ``frame``, interleaved run by run."""
    times = interleaved_ms({"copy": frame.clone, "bloom": lambda: tg.functional.bloom(frame, **settings)}, repeats)
    bloom_times, copy_times = times["bloom"], times["copy"]
    bloom_ms, copy_ms = statistics.median(bloom_times), statistics.median(copy_times)
    return {
        "height": frame.shape[-2],
        "width": frame.shape[-1],
        "settings": settings,
        "bloom_ms": round(bloom_ms, 2),
        "bloom_min_ms": round(min(bloom_times), 2),
        "copy_ms": round(copy_ms, 3),
        "copy_min_ms": round(min(copy_times), 3),
        "ratio_to_copy": round(bloom_ms / copy_ms, 1),
        "ratio_of_minima": round(min(bloom_times) / min(copy_times), 1),
        "ms_per_megapixel": round(bloom_ms / (frame.shape[-2] * frame.shape[-1] / 1e6), 2),
    }


def table(rows: list[dict], label: str, key) -> str:
    lines = [
        f"| {label} | bloom ms (median / min) | copy ms (median / min) | bloom / copy (medians / minima) | ms per MP |",
        "| --- | --- | --- | --- | --- |",
    ]
    for row in rows:
        lines.append(
            f"| {key(row)} | {row['bloom_ms']} / {row['bloom_min_ms']} | {row['copy_ms']} / {row['copy_min_ms']} "
            f"| {row['ratio_to_copy']} / {row['ratio_of_minima']} | {row['ms_per_megapixel']} |"
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    started = time.perf_counter()
    frame = hdr_frame(*FULL_HD)
    variants = [dict(measure(frame, 7, **settings), variant=name) for name, settings in VARIANTS.items()]
    iterations = [measure(frame, 3, max_iterations=n) for n in ITERATIONS]
    resolutions = [measure(hdr_frame(h, w), 7 if h * w < 2e6 else 3) for h, w in RESOLUTIONS]

    machine = f"{platform.processor() or platform.machine()}, {torch.get_num_threads()} threads, torch {torch.__version__}"
    results = {
        "command": COMMAND,
        "machine": machine,
        "python": sys.version.split()[0],
        "frame": "float32 (1, 3, H, W), uniform random in [0, 4)",
        "variants_1080p": variants,
        "max_iterations_1080p": iterations,
        "resolutions_additive": resolutions,
        "seconds": round(time.perf_counter() - started, 1),
    }
    headline = variants[0]
    lines = "\n\n".join(
        [
            "# Bloom on CPU",
            f"`{COMMAND}` on {machine}. Times are the median (and minimum) of several runs; the copy "
            "(`frame.clone()`, the memory floor) is timed alongside each bloom run. Defaults unless stated "
            "(additive, threshold 1, max_iterations 16, fireflies faded, bilinear).",
            f"**1920x1080 float32: bloom {headline['bloom_ms']} ms = {headline['ratio_to_copy']} copies of the frame "
            f"(medians; {headline['ratio_of_minima']} comparing the fastest runs; goal: at most 15).**",
            "## Variants at 1920x1080\n\n" + table(variants, "variant", lambda r: r["variant"]),
            "## max_iterations at 1920x1080\n\n" + table(iterations, "max_iterations", lambda r: r["settings"]["max_iterations"]),
            "## Resolution (additive)\n\n" + table(resolutions, "frame", lambda r: f"{r['width']}x{r['height']}"),
        ]
    )
    write_results(args.out, "bloom", results, lines.splitlines(), COMMAND)


if __name__ == "__main__":
    main()
