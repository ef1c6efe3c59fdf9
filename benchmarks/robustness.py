"""Robustness report: non-finite outputs and gradients of every module on the extreme input families,
and how many damaged EXR and malformed .cube files are rejected cleanly.

The modules and input families are those of ``tests/test_extremes.py`` (imported, so the report
shows exactly what the test suite checks). Writes ``benchmarks/results/robustness.md``.

    .venv/bin/python benchmarks/robustness.py
"""

from __future__ import annotations

import random
import subprocess
import sys
import tempfile
from pathlib import Path

import torch
from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import torchgrade as tg  # noqa: E402
from benchmarks.common import EXR_DIR  # noqa: E402
from test_extremes import MODULES, _families  # noqa: E402

DTYPES = {"float32": torch.float32, "float16": torch.float16, "bfloat16": torch.bfloat16}
FUZZED_FILES = 5000


def non_finite_counts(make, image: torch.Tensor, dtype: torch.dtype) -> tuple[int, int]:
    """Non-finite values in the output (in ``dtype``) and in the float64 gradient for the finite pixels."""
    out = make()(image.to(dtype))
    finite = torch.where(torch.isfinite(image), image, torch.zeros_like(image)).requires_grad_()
    make().double()(finite).sum().backward()
    return int((~torch.isfinite(out)).sum()), int((~torch.isfinite(finite.grad)).sum())


def extremes_table() -> list[str]:
    families = _families(EXR_DIR)
    header = "| module | " + " | ".join(families) + " |"
    rows = [header, "|" + " --- |" * (len(families) + 1)]
    for name, make, _ in tqdm(MODULES, desc="modules"):
        cells = []
        for image in families.values():
            counts = [non_finite_counts(make, image, dtype) for dtype in DTYPES.values()]
            cells.append(" / ".join(str(out) for out, _ in counts) + f" · {counts[0][1]}")
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return rows


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


def mutated_cube(rng: random.Random, valid: bytes) -> bytes:
    """A valid .cube with a random cut, insertion, token swap or truncation."""
    tokens = [b"LUT_3D_SIZE", b"LUT_1D_SIZE", b"DOMAIN_MIN", b"DOMAIN_MAX", b"nan", b"inf", b"-1", b"257", b"1e400", b"\x00", b"\n", b"x", b"9" * 30]
    start = rng.randrange(len(valid) + 1)
    end = min(len(valid), start + rng.randrange(40))
    insert = b" ".join(rng.choice(tokens) for _ in range(rng.randrange(4)))
    return valid[:start] + insert + valid[end:]


def fuzzed_cube_verdicts() -> tuple[int, int, int]:
    """(rejected with ValueError, accepted with a finite table, anything else) over mutated .cube files."""
    rng = random.Random(0)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "valid.cube"
        tg.io.write_cube(path, tg.bake_lut(lambda x: x * 0.5, size=3, shaper="logc"))
        valid = path.read_bytes()
        rejected = accepted = other = 0
        for _ in tqdm(range(FUZZED_FILES), desc=".cube fuzz"):
            path.write_bytes(mutated_cube(rng, valid))
            try:
                lut = tg.io.read_cube(path)
                accepted += bool(torch.isfinite(lut.table).all())
                other += not bool(torch.isfinite(lut.table).all())
            except ValueError:
                rejected += 1
            except Exception:  # noqa: BLE001 - counting anything that is not the documented error
                other += 1
    return rejected, accepted, other


def main() -> None:
    table = extremes_table()
    damaged_rejected, damaged_total = damaged_exr_verdicts()
    rejected, accepted, other = fuzzed_cube_verdicts()
    lines = [
        "Non-finite outputs per module and input family, for float32 / float16 / bfloat16 inputs, "
        "then (after ·) non-finite float64 gradients for the finite pixels:",
        "",
        *table,
        "",
        f"Damaged EXR files (`../shared/data/exr/damaged/`): {damaged_rejected} of {damaged_total} rejected with "
        "ValueError/OSError, none crashed or hung.",
        f"Mutated .cube files: {FUZZED_FILES} generated; {rejected} rejected with ValueError, {accepted} still valid "
        f"(accepted, finite table), {other} failed any other way.",
        "",
        "Command: `.venv/bin/python benchmarks/robustness.py`",
    ]
    out = ROOT / "benchmarks" / "results" / "robustness.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
