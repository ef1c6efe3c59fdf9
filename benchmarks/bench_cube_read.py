"""Reading a 256³ ``.cube`` file (the largest LUT torchgrade bakes): time and peak memory, and how fast
a file of 200 MB of comment lines (80-byte lines, and 2-byte lines, the most lines per byte) is refused.

Each read runs in a fresh Python process, so its peak resident memory (the kernel's ``VmHWM``, minus
the resident memory after the imports) counts only what the read allocates, the returned LUT
included. The table itself is 256³ × 3 float32 = 192 MiB. Writes ``cube_read.json`` and ``cube_read.md``
to ``--out`` (default benchmarks/out; the committed ones with ``--out benchmarks/results``).

Run: ``.venv/bin/python -m benchmarks cube_read [--out DIR]``
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import torch

import torchgrade as tg
from benchmarks.common import argument_parser, write_results

COMMAND = ".venv/bin/python -m benchmarks cube_read"
SIZE = 256
COMMENT_BYTES = 200 << 20

_READ = """
import sys, time
import torchgrade as tg
from benchmarks.common import status_kib
before = status_kib("VmRSS")
start, cpu = time.perf_counter(), time.process_time()
try:
    tg.io.read_cube(sys.argv[1])
    outcome = "read"
except ValueError as error:
    outcome = "refused: " + str(error).split(": ", 1)[-1][:120]
print(time.perf_counter() - start, time.process_time() - cpu, (status_kib("VmHWM") - before) / 1024, outcome, sep="\\t")
"""


def timed_read(path: Path) -> dict:
    """Wall and CPU seconds, peak MiB and outcome of ``read_cube(path)`` in a fresh process.

    CPU seconds are reported beside wall seconds because a loaded machine stretches the latter.
    """
    root = Path(__file__).resolve().parents[1]
    lines = subprocess.run([sys.executable, "-c", _READ, str(path)], capture_output=True, text=True, check=True, cwd=root,
                           env={"PYTHONPATH": str(root)}).stdout
    seconds, cpu, peak, outcome = lines.strip().splitlines()[-1].split("\t")
    return {"seconds": round(float(seconds), 2), "cpu_seconds": round(float(cpu), 2), "peak_mib": round(float(peak)), "outcome": outcome,
            "file_mib": round(path.stat().st_size / 2**20)}


def comment_file(path: Path, line: bytes) -> None:
    """A 256³ header and one data row followed by 200 MB of comment ``line``s: all of it read as data lines."""
    with open(path, "wb") as handle:
        handle.write(b"LUT_3D_SIZE 256\n0 0 0\n")
        for _ in range(COMMENT_BYTES // (len(line) * 1024)):
            handle.write(line * 1024)


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    generator = torch.Generator().manual_seed(0)
    with tempfile.TemporaryDirectory() as folder:
        big = Path(folder) / "256.cube"
        tg.io.write_cube(big, tg.LUT3D(torch.rand(SIZE, SIZE, SIZE, 3, generator=generator)))
        results = {"table_mib": SIZE**3 * 3 * 4 / 2**20, "read_256": timed_read(big)}
        big.unlink()
        comments = Path(folder) / "comments.cube"
        for name, line in (("comments_200mb", b"# " + b"c" * 77 + b"\n"), ("short_comments_200mb", b"#\n")):
            comment_file(comments, line)
            results[name] = timed_read(comments)
    rows = [f"| {name} | {r['file_mib']} | {r['seconds']} | {r['cpu_seconds']} | {r['peak_mib']} | {r['outcome']} |"
            for name, r in results.items() if isinstance(r, dict)]
    table = ["| file | MiB | wall s | CPU s | peak MiB | outcome |", "| --- | --- | --- | --- | --- | --- |", *rows]
    write_results(args.out, "cube_read", results, [f"256³ table: {results['table_mib']:.0f} MiB float32", "", *table], COMMAND)


if __name__ == "__main__":
    main()
