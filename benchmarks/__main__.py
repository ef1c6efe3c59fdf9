"""One door to every benchmark.

    .venv/bin/python -m benchmarks --list
    .venv/bin/python -m benchmarks NAME [--quick] [--out DIR] [NAME's own flags]

``NAME`` is what the benchmark's results are called (``lut_cpu`` writes ``lut_cpu.md`` and ``lut_cpu.json``); the
flags after it go to that benchmark (``python -m benchmarks NAME --help`` lists them). ``--quick`` runs its quick
form, where it has one (``--list`` marks them); ``--out`` is where it writes, default ``benchmarks/out``. One prints
instead: ``cpu_paths`` (``--json FILE`` on request), which imports only torchgrade, so that
``PYTHONPATH=<checkout> .venv/bin/python benchmarks/bench_cpu_paths.py`` times another version with the same script.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from pathlib import Path

HELPERS = frozenset({"common", "metrics", "fuzz", "suite"})
"""Modules of this package that measure nothing on their own."""
RENAMED = {"run": "suite", "compare_runs": "stability", "plot_tonemap": "tonemap"}
"""Modules whose benchmark name is not their file name without ``bench_``."""


def benchmark_name(module: str) -> str:
    """What the benchmark in ``module`` and its results are called.

    Examples:
        >>> benchmark_name("bench_lut_cpu"), benchmark_name("lut_lattices"), benchmark_name("run")
        ('lut_cpu', 'lut_lattices', 'suite')
    """
    return RENAMED.get(module, module.removeprefix("bench_"))


NAMES = {benchmark_name(info.name): info.name for info in pkgutil.iter_modules([str(Path(__file__).parent)])
         if info.name not in HELPERS and not info.name.startswith("_")}
"""Every benchmark: name -> module of this package."""


SUMMARY_WIDTH = 100
"""Characters of a benchmark's first sentence that ``--list`` shows."""


def summary(module) -> str:
    """The start of a benchmark's docstring's first sentence, and whether it has a quick form."""
    first = " ".join((module.__doc__ or "").strip().split("\n\n")[0].split())
    sentence = first.split(". ")[0].rstrip(".").replace("``", "")
    shown = sentence if len(sentence) <= SUMMARY_WIDTH else sentence[:SUMMARY_WIDTH - 1].rstrip() + "…"
    return f"{shown}{' (--quick)' if getattr(module, 'QUICK', None) else ''}"


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    if argv[0] == "--list":
        for name, module in sorted(NAMES.items()):
            print(f"{name:20} {summary(importlib.import_module(f'benchmarks.{module}'))}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in NAMES:
        print(f"no benchmark named {name!r}; one of: {', '.join(sorted(NAMES))}", file=sys.stderr)
        return 2
    module = importlib.import_module(f"benchmarks.{NAMES[name]}")
    if "--quick" in rest and not getattr(module, "QUICK", None):
        print(f"{name} has no quick form (python -m benchmarks --list marks those that do)", file=sys.stderr)
        return 2
    return module.main(rest) or 0


if __name__ == "__main__":
    sys.exit(main())
