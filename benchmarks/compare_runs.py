"""How far two runs of the suite agree: each row's ratios in both runs, and their spread.

    .venv/bin/python -m benchmarks stability FIRST/results.json SECOND/results.json [--out DIR]

For every row timed in both runs: its ratio to the plain frame copy and (per-pixel rows) to OpenColorIO in
each run, and the spread, the larger over the smaller minus 1 (0.2: the runs differ by 20 %); the same for the
whole-look check. Each run's wall time and load averages are listed too. Writes ``stability.json`` and
``.md`` (quick or full runs alike; the table says which) to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``).
"""

from __future__ import annotations

import json
from pathlib import Path


from benchmarks.common import argument_parser, write_results

RATIOS = {"ratio_to_copy": "× copy", "ratio_to_opencolorio": "× OCIO"}
"""The ratios a run reports per row, and their column names."""
BAR = 0.2
"""The spread two runs may show and still count as agreeing."""


def spread(first: float, second: float) -> float:
    """The larger over the smaller, minus 1."""
    return max(first, second) / min(first, second) - 1.0


def ratio_rows(first: dict, second: dict) -> list:
    """``{"method", "ratio", "first", "second", "spread"}`` for every ratio both runs measured, and the whole-look check."""
    theirs = {r["method"]: r for r in second["rows"]}
    rows = [{"method": r["method"], "ratio": label, "first": r[key], "second": theirs[r["method"]][key],
             "spread": spread(r[key], theirs[r["method"]][key])}
            for r in first["rows"] if r["method"] in theirs for key, label in RATIOS.items()
            if r.get(key) is not None and theirs[r["method"]].get(key) is not None]
    if first.get("check") and second.get("check"):
        a, b = first["check"]["whole_over_parts"], second["check"]["whole_over_parts"]
        rows.append({"method": "eager whole look", "ratio": "/ (bloom + per-pixel)", "first": a, "second": b, "spread": spread(a, b)})
    return rows


def run_line(name: str, run: dict) -> str:
    load = " / ".join(f"{x:.2f}" for x in run["environment"]["load_average"])
    return f"- {name}: `{run['command']}`, {run['wall_s']:.0f} s, {run['runs']} rounds, load average {load} (1 / 5 / 15 min) at its end"


def markdown(rows: list, first: dict, second: dict) -> list:
    within = sum(r["spread"] <= BAR for r in rows)
    worst = max(rows, key=lambda r: r["spread"])
    return [
        f"# Two runs of python -m benchmarks suite{' --quick' if first['quick'] else ''}: do their ratios agree?", "",
        run_line("first", first), run_line("second", second), "",
        f"{within} of {len(rows)} ratios within {BAR:.0%} of each other; the widest: {worst['method']} {worst['ratio']}, "
        f"{worst['spread']:.0%}.", "",
        "| row | ratio | first | second | spread |", "| --- | --- | ---: | ---: | ---: |",
        *[f"| {r['method']} | {r['ratio']} | {r['first']:.2f} | {r['second']:.2f} | {r['spread']:.0%} |" for r in rows],
    ]


def main(argv=None) -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("first", type=Path, help="results.json of the first run")
    parser.add_argument("second", type=Path, help="results.json of the second run")
    args = parser.parse_args(argv)
    first, second = (json.loads(path.read_text()) for path in (args.first, args.second))
    rows = ratio_rows(first, second)
    report = {"first": first["command"], "second": second["command"], "bar": BAR, "rows": rows,
              "within_bar": sum(r["spread"] <= BAR for r in rows)}
    command = f".venv/bin/python -m benchmarks stability {args.first} {args.second}"
    write_results(args.out, "stability", report, markdown(rows, first, second), command)


if __name__ == "__main__":
    main()
