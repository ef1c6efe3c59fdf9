"""Robustness report: non-finite outputs and gradients of every stage on the extreme input families,
every control swept across its documented range, the error autocast would cause, how many damaged
EXR and malformed .cube files are rejected cleanly, and what reading a 256³ .cube costs.

The stages are :data:`torchgrade.testing.catalog.STAGE_KINDS` and the inputs
:func:`torchgrade.testing.extremes.extreme_inputs`, the listing ``tests/library/test_extremes.py`` and
``tests/library/test_control_ranges.py`` check too. Writes ``robustness.md`` and ``robustness_controls.md`` (the control
sweep and autocast, alone with ``--controls``) to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``).

    .venv/bin/python -m benchmarks robustness [--controls | --fuzz] [--out DIR]
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
import tempfile
from pathlib import Path

import torch
from tqdm import tqdm

import torchgrade as tg
import torchgrade.base.stage
from benchmarks.bench_cube_read import timed_read
from benchmarks.common import EXR_DIR, argument_parser, write_markdown
from benchmarks.fuzz import DEFECTS_FREE, FAMILIES
from torchgrade.testing.catalog import STAGE_KINDS
from torchgrade.testing.extremes import extreme_inputs

ROOT = Path(__file__).resolve().parents[1]

DTYPES = {"float32": torch.float32, "float16": torch.float16, "bfloat16": torch.bfloat16}
FUZZED_FILES = 2000


def non_finite_counts(make, image: torch.Tensor, dtype: torch.dtype) -> tuple[int, int]:
    """Non-finite values in the output (in ``dtype``) and in the float64 gradient for the finite pixels."""
    out = make()(image.to(dtype))
    finite = torch.where(torch.isfinite(image), image, torch.zeros_like(image)).requires_grad_()
    make().double()(finite).sum().backward()
    return int((~torch.isfinite(out)).sum()), int((~torch.isfinite(finite.grad)).sum())


def extremes_table() -> list[str]:
    families = extreme_inputs(EXR_DIR)
    header = "| stage | " + " | ".join(families) + " |"
    rows = [header, "|" + " --- |" * (len(families) + 1)]
    for name, kind in tqdm(STAGE_KINDS.items(), desc="stages"):
        cells = []
        for image in families.values():
            counts = [non_finite_counts(kind.example, image, dtype) for dtype in DTYPES.values()]
            cells.append(" / ".join(str(out) for out, _ in counts) + f" · {counts[0][1]}")
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return rows


# Extreme finite pixels, every combination of three per pixel: what a documented control must survive (1e-40: a
# float32 denormal whose square underflows).
SWEEP_PIXELS = (0.0, 1e-40, 1e-38, 0.18, 1.0, 60.0, 65504.0, -1.0, -65504.0)
SWEEP_POINTS = 9
PLAIN_NUMBERS = ("peak_luminance",)  # ACES 2.0 caches its tables per peak: a plain number, not a tensor


def number_controls(module) -> dict:
    """The stage's number controls (``{name: Control}``); none for a module that is not a stage."""
    table = module.control_table() if isinstance(module, torchgrade.base.stage.Stage) else {}
    return {name: c for name, c in table.items() if c.kind == "number"}


def swept_stages() -> dict:
    """The stages with number controls (ACES 2.0's ``peak_luminance`` included: it takes plain numbers), ``{name: build}``;
    built on demand, not at import (building every stage takes seconds)."""
    return {name: kind.build for name, kind in STAGE_KINDS.items() if number_controls(kind.build())}


def sweep_image() -> torch.Tensor:
    grid = torch.cartesian_prod(*[torch.tensor(SWEEP_PIXELS)] * 3)
    return grid.T.reshape(1, 3, len(SWEEP_PIXELS), -1).contiguous()


def swept_settings(make) -> list[dict]:
    """Each number control at SWEEP_POINTS values across its range (others at defaults), then all at their low, then high, edges."""
    table = number_controls(make())
    shapes = {name: torch.as_tensor(c.default if c.default is not None else 0.0, dtype=torch.float32).shape for name, c in table.items()}
    settings = [
        {name: torch.full(shapes[name], float(v))}
        for name, c in table.items()
        for v in torch.linspace(c.range[0], c.range[1], SWEEP_POINTS, dtype=torch.float64)
    ]
    for edge in (0, 1):
        settings.append({name: torch.full(shapes[name], float(c.range[edge])) for name, c in table.items()})
    return settings


def sweep_counts(make) -> tuple[int, int, int, int]:
    """(settings run, settings refused by a rule between controls, non-finite outputs, non-finite gradients)."""
    run = refused = outputs = gradients = 0
    for setting in swept_settings(make):
        controls = {name: float(value) if name in PLAIN_NUMBERS else value.clone().requires_grad_() for name, value in setting.items()}
        try:
            module = make(**controls)
        except ValueError:
            refused += 1
            continue
        image = sweep_image().requires_grad_()
        out = module(image)
        out.sum().backward()
        run += 1
        outputs += int((~torch.isfinite(out)).sum())
        grads = [image.grad] + [c.grad for c in controls.values() if isinstance(c, torch.Tensor) and c.grad is not None]
        gradients += sum(int((~torch.isfinite(g)).sum()) for g in grads)
    return run, refused, outputs, gradients


def sweep_table() -> list[str]:
    rows = ["| module | settings run | refused (cross-control rule) | non-finite outputs | non-finite gradients |", "| --- | --- | --- | --- | --- |"]
    for name, make in tqdm(swept_stages().items(), desc="control sweep"):
        rows.append(f"| {name} | " + " | ".join(map(str, sweep_counts(make))) + " |")
    return rows


def autocast_codes() -> tuple[float, float]:
    """Max 8-bit sRGB code error of ColorGrade(contrast=20, saturation=10, aces=True) + ToneMap("aces") on Desk
    under CPU bfloat16 autocast, against float32: (stages as shipped, stages with the autocast guard removed)."""
    image = tg.io.read_exr(EXR_DIR / "Desk.exr")[:3].unsqueeze(0)
    look = torch.nn.Sequential(tg.ColorGrade(contrast=20, saturation=10, aces=True), tg.ToneMap("aces"))
    codes = lambda display: tg.color.linear_to_srgb(display.double().clamp(0.0, 1.0)) * 255.0  # noqa: E731
    reference = codes(look(image))
    errors = []
    for guard in (torchgrade.base.stage.full_precision, contextlib.nullcontext):
        shipped, torchgrade.base.stage.full_precision = torchgrade.base.stage.full_precision, guard
        try:
            with torch.autocast("cpu", dtype=torch.bfloat16):
                errors.append(float((codes(look(image)) - reference).abs().max()))
        finally:
            torchgrade.base.stage.full_precision = shipped
    return errors[0], errors[1]


def damaged_exr_verdicts() -> tuple[int, int]:
    """(rejected with ValueError/OSError, total) over ``damaged/``, read in a child process."""
    script = (
        "import sys, pathlib, torchgrade as tg\n"
        "for p in sorted(pathlib.Path(sys.argv[1]).iterdir()):\n"
        "    if p.suffix == '.rst': continue\n"
        "    try: tg.io.read_exr(p); print('VERDICT accepted')\n"
        "    except (ValueError, OSError): print('VERDICT rejected')\n"
    )
    result = subprocess.run([sys.executable, "-c", script, str(EXR_DIR / "damaged")], capture_output=True, text=True, timeout=600)
    verdicts = [line for line in result.stdout.splitlines() if line.startswith("VERDICT ")]
    return sum(v == "VERDICT rejected" for v in verdicts), len(verdicts)


def fuzz_report(count: int) -> list[str]:
    """The counts of :mod:`benchmarks.fuzz`'s verdicts for ``count`` mutations of each family."""
    lines = ["| family | mutations | refused (ValueError) | accepted (finite) | anything else |", "| --- | ---: | ---: | ---: | --- |"]
    for family, verdicts_of in tqdm(FAMILIES.items(), desc="fuzz"):
        verdicts = verdicts_of(count, seed=0)
        others = ", ".join(f"{n} {verdict}" for verdict, n in verdicts.items() if verdict not in DEFECTS_FREE) or "0"
        lines.append(f"| {family} | {sum(verdicts.values())} | {verdicts['refused']} | {verdicts['accepted']} | {others} |")
    return lines


def cube_256_read() -> dict:
    """Wall and CPU seconds and peak MiB of reading a 256³ .cube file (the largest LUT torchgrade bakes), in a fresh process."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "256.cube"
        tg.io.write_cube(path, tg.LUT3D(torch.rand(256, 256, 256, 3, generator=torch.Generator().manual_seed(0))))
        return timed_read(path)


def controls_report() -> list[str]:
    sweep = sweep_table()
    guarded, unguarded = autocast_codes()
    return [
        f"Every number control swept across its documented range ({SWEEP_POINTS} values per control, edges included, the "
        "others at defaults; then all at their low and all at their high edges) on every combination of "
        f"{SWEEP_PIXELS} per channel, float32; gradients with respect to the image and the controls:",
        "",
        *sweep,
        "",
        f"Autocast: ColorGrade(contrast=20, saturation=10, aces=True) + ToneMap(\"aces\") on Desk.exr under CPU bfloat16 "
        f"autocast, max error against float32: {guarded:.2f} 8-bit codes (without the stages' autocast guard: {unguarded:.1f}).",
        "",
        "Command: `.venv/bin/python -m benchmarks robustness --controls` (also part of the full run)",
    ]


def inputs_report() -> list[str]:
    table = extremes_table()
    damaged_rejected, damaged_total = damaged_exr_verdicts()
    fuzzed = fuzz_report(FUZZED_FILES)
    cube = cube_256_read()
    return [
        "Non-finite outputs per module and input family, for float32 / float16 / bfloat16 inputs, "
        "then (after ·) non-finite float64 gradients for the finite pixels:",
        "",
        *table,
        "",
        f"Damaged EXR files (`../shared/data/exr/damaged/`): {damaged_rejected} of {damaged_total} rejected with "
        "ValueError/OSError, none crashed or hung.",
        "Fuzzed inputs (`benchmarks/fuzz.py`, seed 0): EXR headers and chunk tables, .cube files, CLF writes, look configs:",
        "",
        *fuzzed,
        "",
        f"A 256³ .cube file ({cube['file_mib']} MiB, a 192 MiB float32 table) reads in {cube['cpu_seconds']} s of CPU "
        f"({cube['seconds']} s wall) with a peak of {cube['peak_mib']} MiB (fresh process, `benchmarks/bench_cube_read.py`'s reader).",
        "",
        "Command: `.venv/bin/python -m benchmarks robustness`",
    ]


def main(argv=None) -> None:
    """The full report (robustness.md and robustness_controls.md); ``--controls`` writes only the second (a minute),
    ``--fuzz`` only the fuzzing counts (robustness_fuzz.md, a few minutes)."""
    parser = argument_parser(__doc__)
    only = parser.add_mutually_exclusive_group()
    only.add_argument("--controls", action="store_true", help="only the control sweep and autocast (robustness_controls.md)")
    only.add_argument("--fuzz", action="store_true", help="only the fuzzing counts (robustness_fuzz.md)")
    args = parser.parse_args(argv)

    def write(name: str, lines: list) -> None:
        write_markdown(args.out, name, lines)
        print("\n".join(lines))

    if args.fuzz:
        write("robustness_fuzz.md", [f"{FUZZED_FILES} mutations of each family (`benchmarks/fuzz.py`, seed 0):", "",
                                     *fuzz_report(FUZZED_FILES), "", "Command: `.venv/bin/python -m benchmarks robustness --fuzz`"])
        return
    write("robustness_controls.md", controls_report())
    if not args.controls:
        write("robustness.md", inputs_report())


if __name__ == "__main__":
    main()
