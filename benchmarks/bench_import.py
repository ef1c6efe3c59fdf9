"""``import torchgrade`` after ``import torch``: seconds, and what it loads that only some calls need.

Each import runs in a fresh Python process with its bytecode cached (the first process of a checkout writes it, and is
not counted), the checkouts compared alternating (A B A B). ``--vs DIR`` imports the torchgrade of another checkout
beside this one's. Also lists the modules of :data:`LOADED_AT_FIRST_USE` that the import loaded (none expected: ONNX's
exporter, the compiler and the optional packages load at their first use).

    python -m benchmarks import [--out DIR] [--runs N] [--vs CHECKOUT]

Writes ``import.json`` and ``import.md`` to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path


from benchmarks.common import ROOT, argument_parser, write_results

LOADED_AT_FIRST_USE = ("torch.onnx", "torch._dynamo", "kornia", "onnx", "onnxruntime", "OpenEXR", "Imath", "PIL", "scipy",
                       "PyOpenColorIO", "colour", "matplotlib")
"""Modules ``import torchgrade`` should leave to the first call that needs them (``tests/runtime/test_policies.py``,
``tests/project/test_import.py``)."""

_IMPORT = """
import json, sys, time
import torch
names = {names!r}
start = time.perf_counter()
import torchgrade
seconds = time.perf_counter() - start
print(json.dumps({{"seconds": seconds, "file": torchgrade.__file__,
                  "loaded": [n for n in names if any(m == n or m.startswith(n + ".") for m in sys.modules)]}}))
"""


def import_once(checkout: Path, write_bytecode: bool = True) -> dict:
    """``import torchgrade`` of ``checkout`` in a fresh process (that writes its bytecode, unless ``write_bytecode`` is
    False: the environment's setting then holds): seconds, and which of :data:`LOADED_AT_FIRST_USE` it loaded."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    if write_bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    result = subprocess.run([sys.executable, "-c", _IMPORT.format(names=LOADED_AT_FIRST_USE)], capture_output=True, text=True,
                            env=env, cwd=checkout, timeout=300, check=True)
    once = json.loads(result.stdout.strip().splitlines()[-1])
    if not Path(once["file"]).resolve().is_relative_to(checkout.resolve()):
        raise RuntimeError(f"{checkout} imported torchgrade from {once['file']}: is it a checkout?")
    return once


def revision(checkout: Path) -> str:
    """The commit a checkout is at, with ``+`` when its tracked files differ from it."""
    def git(*command):
        return subprocess.run(["git", "-C", str(checkout), *command], capture_output=True, text=True).stdout.strip()
    commit = git("rev-parse", "--short", "HEAD") or "not a git checkout"
    return commit + ("+" if git("status", "--porcelain", "--untracked-files=no") else "")


def main(argv=None) -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--runs", type=int, default=9)
    parser.add_argument("--vs", type=Path, default=None, help="another checkout, imported alternately with this one")
    args = parser.parse_args(argv)
    checkouts = {"this checkout": ROOT, **({"--vs checkout": args.vs.resolve()} if args.vs else {})}
    for checkout in checkouts.values():
        import_once(checkout)  # writes the bytecode
    seconds = {name: [] for name in checkouts}
    loaded = {}
    for run in range(args.runs):
        order = list(checkouts) if run % 2 == 0 else list(reversed(checkouts))
        for name in order:
            once = import_once(checkouts[name])
            seconds[name].append(once["seconds"])
            loaded[name] = once["loaded"]
    rows = [{"checkout": f"{name} ({revision(checkouts[name])})", "median_s": round(statistics.median(values), 3),
             "min_s": round(min(values), 3), "max_s": round(max(values), 3),
             "loaded_at_import": loaded[name]}
            for name, values in seconds.items()]
    lines = ["# `import torchgrade` after `import torch`", "",
             f"Fresh processes with cached bytecode, {args.runs} a checkout, alternating; loaded at import: the modules of "
             f"{', '.join(f'`{n}`' for n in LOADED_AT_FIRST_USE)} that the import loaded.", "",
             "| checkout | median s | min s | max s | loaded at import |", "| --- | ---: | ---: | ---: | --- |"]
    lines += [f"| {r['checkout']} | {r['median_s']} | {r['min_s']} | {r['max_s']} | {', '.join(r['loaded_at_import']) or 'none'} |"
              for r in rows]
    args.out.mkdir(parents=True, exist_ok=True)
    write_results(args.out, "import", {"runs": args.runs, "rows": rows}, lines,
                  "python -m benchmarks import --out DIR" + (" --vs CHECKOUT" if args.vs else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
