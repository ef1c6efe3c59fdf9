"""Throughput of ``RandomPostFX`` against kornia's ``ColorJiggle``, measured in the same run.

Three layers on the same batch (default 32x3x224x224 float32, CPU, torch's default thread count):

* ``ColorJiggle``: brightness, contrast, saturation and hue (kornia's colour augmentation);
* ``RandomPostFX``, comparable controls: post exposure, contrast, saturation and hue shift, on linear light;
* the same controls on sRGB-encoded images (``input_space="srgb"``: decoded, graded, encoded), as LDR training sets
  hold them (the batch divided by 4, into [0, 1));
* ``RandomPostFX``, full set: every grading control, bloom, and a per-sample tone mapper.

The ranges are in the JSON. Runs are interleaved (one of each layer per round), so a busy machine slows all of them alike; the
median of the rounds after a warm-up is reported (:func:`benchmarks.common.median_ms`), with its ratio to ColorJiggle's median.
Writes ``augment.json`` and ``augment.md`` to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``). With ``--device cuda`` it measures
on the GPU (default batch 256 there) and writes ``augment_cuda.json`` / ``augment_cuda.md``.

    .venv/bin/python -m benchmarks augment [--device cuda] [--batch N] [--resolution N] [--rounds N]
"""

from __future__ import annotations

import functools
import platform
import sys

import kornia
import torch
from kornia.augmentation import ColorJiggle


import torchgrade as tg
from benchmarks.common import argument_parser, median_ms, synchronizer, write_results


JIGGLE = dict(brightness=0.2, contrast=0.2, saturation=0.2, hue=0.1)

COMPARABLE = dict(post_exposure=(-0.5, 0.5), contrast=(-20.0, 20.0), saturation=(-20.0, 20.0), hue_shift=(-36.0, 36.0))
"""RandomPostFX ranges matching the ColorJiggle below (hue 0.1 of a turn = 36 degrees)."""

FULL = dict(
    COMPARABLE,
    temperature=(-20.0, 20.0),
    tint=(-20.0, 20.0),
    split_shadows=(0.4, 0.6),
    split_highlights=(0.4, 0.6),
    split_balance=(-30.0, 30.0),
    bloom_threshold=(0.8, 1.2),
    bloom_intensity=(0.0, 1.0),
    tonemap=("neutral", "aces", "reinhard"),
)


def layers() -> dict:
    """The layers measured, by label."""
    return {
        "ColorJiggle(brightness, contrast, saturation, hue)": ColorJiggle(**JIGGLE, p=1.0),
        "RandomPostFX(post_exposure, contrast, saturation, hue_shift)": tg.RandomPostFX(**COMPARABLE),
        'RandomPostFX(same, input_space="srgb")': tg.RandomPostFX(**COMPARABLE, input_space="srgb"),
        "RandomPostFX(full set + bloom + tone mapper choice)": tg.RandomPostFX(**FULL),
    }


def batch(size: int, resolution: int, device: str) -> torch.Tensor:
    """An HDR-ish batch in [0, 4) (ColorJiggle clamps to [0, 1]; the cost does not depend on values)."""
    generator = torch.Generator().manual_seed(0)
    return (4.0 * torch.rand(size, 3, resolution, resolution, generator=generator)).to(device)


def measure(images: torch.Tensor, rounds: int, warmup: int) -> dict:
    """Median ms per batch of each layer, rounds interleaved across layers."""
    display = images / 4.0  # sRGB codes in [0, 1) for the sRGB layer
    calls = {label: functools.partial(layer, display if getattr(layer, "input_space", None) == "srgb" else images)
             for label, layer in layers().items()}
    return median_ms(calls, rounds, warmup, sync=synchronizer(images.device))


def report(medians: dict, images: torch.Tensor, rounds: int, command: str) -> dict:
    baseline = next(iter(medians.values()))
    rows = [
        {
            "layer": label,
            "ms_per_batch": round(ms, 2),
            "images_per_s": round(1e3 * images.shape[0] / ms, 1),
            "ratio_to_colorjiggle": round(ms / baseline, 3),
        }
        for label, ms in medians.items()
    ]
    return {
        "batch": list(images.shape),
        "dtype": str(images.dtype).replace("torch.", ""),
        "device": str(images.device) if not images.is_cuda else torch.cuda.get_device_name(images.device),
        "threads": torch.get_num_threads(),
        "rounds": rounds,
        "statistic": "median of interleaved rounds after warm-up",
        "torch": torch.__version__,
        "kornia": kornia.__version__,
        "python": platform.python_version(),
        "command": command,
        "colorjiggle": JIGGLE,
        "randompostfx_comparable": COMPARABLE,
        "randompostfx_full": FULL,
        "results": rows,
    }


def markdown(result: dict) -> str:
    shape = "x".join(str(n) for n in result["batch"])
    lines = [
        f"# RandomPostFX vs kornia ColorJiggle ({result['device']}, {shape} {result['dtype']}, {result['threads']} threads)",
        "",
        f"{result['statistic']}, {result['rounds']} rounds; torch {result['torch']}, kornia {result['kornia']}.",
        f"Reproduce: `{result['command']}`",
        "",
        "| layer | ms / batch | images / s | ratio to ColorJiggle |",
        "| --- | ---: | ---: | ---: |",
    ]
    lines += [f"| {r['layer']} | {r['ms_per_batch']} | {r['images_per_s']} | {r['ratio_to_colorjiggle']} |" for r in result["results"]]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--batch", type=int, default=None, help="batch size (default 32 on CPU, 256 on CUDA)")
    parser.add_argument("--resolution", type=int, default=224)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--warmup", type=int, default=1)
    args = parser.parse_args(argv)
    size = args.batch or (256 if args.device.startswith("cuda") else 32)
    command = " ".join([".venv/bin/python", "benchmarks/bench_augment.py", *sys.argv[1:]])
    images = batch(size, args.resolution, args.device)
    result = report(measure(images, args.rounds, args.warmup), images, args.rounds, command)
    suffix = "" if args.device == "cpu" else "_" + args.device.split(":")[0]
    write_results(args.out, f"augment{suffix}", result, markdown(result).splitlines(), command, args.device)


if __name__ == "__main__":
    main()
