"""The benchmarks' figures on the pages that quote them, written from the committed results and only from them.

    .venv/bin/python -m benchmarks suite --pages

A page marks each generated block ``<!-- suite:NAME -->`` … ``<!-- /suite:NAME -->`` (invisible in rendered
Markdown); :func:`main` rewrites every block of :data:`PAGES` from :data:`COMMITTED` (the full form's results where
they are committed, else the quick form's, and says which) and from the tables ``bench_match``, ``lut_footage``,
``look_floor`` and ``serving`` mark in their results (:data:`MATCH_TABLES`, :data:`LUT_TABLES`, :data:`FLOOR_TABLES`, :data:`SERVING_TABLES`), and nothing outside the blocks. ``tests/project/test_suite_results.py`` holds each page to
what :func:`filled` would write, and keeps the suite's figures (``ms/MP``, ``× OCIO``) out of every page but inside
its blocks; ``tests/project/test_match_results.py`` and ``tests/project/test_lut_footage_results.py`` hold the match
and LUT report results to the code that wrote them.
``--committed`` (see ``benchmarks/run.py``) runs both forms of the suite and then this.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from benchmarks.common import RESULTS, ROOT
from benchmarks.suite.report import baselines_text, markdown_table, provenance
from benchmarks.suite.runtimes import PEER
from torchgrade.io.atomic import atomic_write

__all__ = ["COMMITTED", "PAGES", "BLOCK", "MATCH", "MATCH_TABLES", "TABLE", "LUT_FOOTAGE", "LUT_TABLES", "committed",
           "marked_results", "match_committed", "quoted_blocks", "LOOK_FLOOR", "FLOOR_TABLES", "SERVING", "SERVING_TABLES", "blocks", "filled", "stale", "main"]

COMMITTED = {"quick": RESULTS / "suite" / "quick", "full": RESULTS / "suite" / "full"}
"""Where each form's committed results live."""
PAGES = (ROOT / "docs" / "performance.md", ROOT / "README.md", ROOT / "docs" / "match.md", ROOT / "docs" / "lut.md",
         ROOT / "docs" / "onnx.md")
"""The pages that quote the benchmarks."""


def marks(kind: str) -> re.Pattern:
    """The pattern of a block marked ``<!-- KIND:NAME -->`` … ``<!-- /KIND:NAME -->``: its ``name`` and ``body``."""
    return re.compile(rf"<!-- {kind}:(?P<name>[\w-]+) -->\n(?P<body>.*?)<!-- /{kind}:(?P=name) -->", re.S)


BLOCK = marks("suite")
"""A block of a page, which this module writes."""
TABLE = marks("match")
"""A table ``bench_match`` marks in its results (``bench_match.marked``)."""
MATCH = {"quick": RESULTS / "match_quick", "full": RESULTS / "match"}
"""Where each form of ``python -m benchmarks match`` commits its results (``.md`` and ``.json``)."""
MATCH_TABLES = {"match-known": "known", "match-reach": "reach", "match-photograph": "photograph"}
"""The page's blocks that quote a table of the quick form's results (accuracy only: a busy machine may make them)."""
MATCH_TIMED = ("photograph", "jacobian")
"""The full form's tables the ``match-timing`` block quotes: seconds and milliseconds, so only from a quiet run."""
MATCH_FULL = ".venv/bin/python -m benchmarks match --out benchmarks/results"
LUT_FOOTAGE = RESULTS / "lut_footage"
"""Where ``python -m benchmarks lut_footage`` commits its results (``.md`` and ``.json``)."""
LUT_TABLES = {"lut-footage": "ratios", "lut-frames": "frames"}
"""docs/lut.md's blocks, each quoting a table ``lut_footage`` marks ``<!-- lut:NAME -->`` (accuracy only)."""
LOOK_FLOOR = RESULTS / "look_floor"
"""Where ``python -m benchmarks look_floor`` commits its results (``.md`` and ``.json``)."""
FLOOR_TABLES = {"floor-time": "time"}
"""docs/performance.md's block quoting the timed table ``look_floor`` marks ``<!-- floor:time -->`` (a quiet run's)."""
SERVING = RESULTS / "serving"
"""Where ``python -m benchmarks serving`` commits its results (``.md`` and ``.json``)."""
SERVING_TABLES = {"serving-load": "load"}
"""docs/onnx.md's block quoting the table ``serving`` marks ``<!-- serving:load -->``."""
QUICK_OUT = "/tmp/torchgrade-bench"
"""Where the README's quick command writes (not the committed results)."""


def committed() -> dict:
    """Each form's committed ``results.json``, by form, for the forms committed."""
    return {form: json.loads((folder / "results.json").read_text(encoding="utf-8"))
            for form, folder in COMMITTED.items() if (folder / "results.json").is_file()}


def headline(results: dict) -> dict:
    """The results the performance page shows: the full form's where committed, else the quick form's."""
    return results.get("full") or results["quick"]


def form_of(report: dict) -> str:
    return "quick" if report["quick"] else "full"


def condition(report: dict) -> str:
    """The machine a run had, from its recorded environment: cores and the 1-minute load average at its end (quiet: at
    most one more than the cores, which the run's own threads fill)."""
    env = report["environment"]
    load = env["load_average"][0]
    quiet = load <= env["cpu_count"] + 1
    return f"{'a quiet' if quiet else 'a busy'} {env['cpu_count']}-core machine (load average {load:.1f})"


def timing_line(report: dict) -> str:
    rows = sum("error" not in r for r in report["rows"])
    return (f"The {form_of(report)} form ({rows} rows) took {report['wall_s']:.0f} s on {condition(report)}, "
            f"{report['cpu_s']:.0f} s of CPU time, at commit `{(report.get('commit') or 'none')[:7]}`"
            f"{' with uncommitted changes' if report.get('modified') else ''}.")


def look_block(results: dict) -> str:
    look = headline(results)["look"]
    stages = "; ".join(f"{slot} `{json.dumps(settings, separators=(', ', ': '))}`" for slot, settings in look.items())
    return f"The look, as `PostFX.from_config` takes it: {stages}.\n"


def table_block(results: dict) -> str:
    report = headline(results)
    form, shown = form_of(report), [r for r in report["rows"] if r.get("headline", True)]
    return "\n".join([
        f"From the {form} form ([all {len(report['rows'])} rows](../benchmarks/results/suite/{form}/results.md)). "
        f"{provenance(report)} On {condition(report)}. Speed: median of {report['runs']} alternated rounds at "
        f"1920×1080; × copy and × OCIO are medians of each round's ratio to a plain frame copy and to {PEER}. "
        "Per-pixel rows leave out the live stages, "
        f"which every look adds: {baselines_text(report)}. Accuracy: the whole look on {', '.join(report['scenes'])} "
        "against the float64 look.",
        "",
        markdown_table(shown),
        "",
        f"![Speed vs accuracy](../benchmarks/results/suite/{form}/pareto.png)",
        "",
    ])


def advice_block(results: dict) -> str:
    return "\n".join(f"- {line}" for line in headline(results)["advice"]) + "\n"


def reproduce_block(results: dict) -> str:
    lines = ["```sh", ".venv/bin/python -m benchmarks suite --committed   # both forms, then these pages' figures", "```", ""]
    lines += [f"- `{report['command']}`: {timing_line(report)}" for report in results.values()]
    return "\n".join(lines) + "\n"


def readme_block(results: dict) -> str:
    return "\n".join(["```sh", f".venv/bin/python -m benchmarks suite --quick --out {QUICK_OUT}", "```", "",
                      f"{timing_line(results['quick'])} It prints a short table; the files hold the rest.", ""])


def marked_results(stem: Path, kind: str) -> dict:
    """A benchmark's committed results at ``stem``: its ``.json`` as ``report`` and the tables its ``.md`` marks
    ``<!-- KIND:NAME -->`` (``benchmarks.common.mark_table``), by name, as ``tables``."""
    return {"report": json.loads(stem.with_suffix(".json").read_text(encoding="utf-8")),
            "tables": {m["name"]: m["body"] for m in marks(kind).finditer(stem.with_suffix(".md").read_text(encoding="utf-8"))}}


def match_committed() -> dict:
    """Each committed form of ``bench_match``'s results, by form (:func:`marked_results`)."""
    return {form: marked_results(stem, "match") for form, stem in MATCH.items() if stem.with_suffix(".json").is_file()}


def results_source(stem: Path, report: dict) -> str:
    """Where a block's figures come from: the results file at ``stem``, the command and the commit."""
    modified = " with uncommitted changes" if report["modified"] else ""
    return (f"From [{stem.name}.md](../benchmarks/results/{stem.name}.md), made by `{report['command']}` at "
            f"commit `{report['commit'][:7]}`{modified}.")


def match_quick_block(table: str, results: dict) -> str:
    if "quick" not in results:
        raise ValueError(f"no committed {MATCH['quick'].name}.json: run .venv/bin/python -m benchmarks match --quick --out benchmarks/results")
    return f"{results_source(MATCH['quick'], results['quick']['report'])}\n\n{results['quick']['tables'][table]}"


def match_timing_block(results: dict) -> str:
    if "full" not in results:
        return (f"The timed run is not committed yet: `{MATCH_FULL}` on a quiet machine writes "
                "`benchmarks/results/match.md`, and `.venv/bin/python -m benchmarks suite --pages` then writes its seconds here.\n")
    report = results["full"]["report"]
    return "\n".join([f"{results_source(MATCH['full'], report)} On {condition(report)}, {report['threads']} torch thread(s).", "",
                      *(results["full"]["tables"][name] for name in MATCH_TIMED if name in results["full"]["tables"])])


def match_blocks() -> dict:
    """The body of every block that quotes ``bench_match``, from its committed results."""
    results = match_committed()
    return {"match-timing": match_timing_block(results),
            **{block: match_quick_block(table, results) for block, table in MATCH_TABLES.items()}}


def quoted_blocks(stem: Path, kind: str, tables: dict) -> dict:
    """The body of every block of ``tables`` (``{block: table}``) that quotes a table the committed results at ``stem``
    mark ``<!-- KIND:TABLE -->``, each with where it comes from."""
    if not stem.with_suffix(".json").is_file():
        raise ValueError(f"no committed {stem.name}.json: run .venv/bin/python -m benchmarks {stem.name} --out benchmarks/results")
    results = marked_results(stem, kind)
    missing = sorted(set(tables.values()) - set(results["tables"]))
    if missing:
        raise ValueError(f"{stem.name}.md marks no table {missing}: run .venv/bin/python -m benchmarks {stem.name} "
                         "--out benchmarks/results (without --counts) on a quiet machine")
    source = results_source(stem, results["report"])
    return {block: f"{source}\n\n{results['tables'][table]}" for block, table in tables.items()}


RENDERERS = {"look": look_block, "table": table_block, "advice": advice_block, "reproduce": reproduce_block,
             "quick": readme_block}
"""Every block a page may hold, by name."""


def blocks(results: dict) -> dict:
    """The body of every block, from the suite's ``results`` (:func:`committed`), ``bench_match``'s
    (:func:`match_blocks`), ``lut_footage``'s and ``look_floor``'s (:func:`quoted_blocks`)."""
    return {**{name: render(results) for name, render in RENDERERS.items()}, **match_blocks(),
            **quoted_blocks(LUT_FOOTAGE, "lut", LUT_TABLES), **quoted_blocks(LOOK_FLOOR, "floor", FLOOR_TABLES),
            **quoted_blocks(SERVING, "serving", SERVING_TABLES)}


def filled(text: str, bodies: dict) -> str:
    """``text`` with every marked block's body replaced by ``bodies[name]``; an unknown block name is an error."""
    def fill(match: re.Match) -> str:
        name = match["name"]
        if name not in bodies:
            raise ValueError(f"no suite block named {name!r}; the blocks are {sorted(bodies)}")
        return f"<!-- suite:{name} -->\n{bodies[name]}<!-- /suite:{name} -->"

    return BLOCK.sub(fill, text)


def stale(page: Path, bodies: dict) -> list:
    """The names of ``page``'s blocks whose text is not what :func:`filled` writes."""
    return [m["name"] for m in BLOCK.finditer(page.read_text(encoding="utf-8")) if m["body"] != bodies.get(m["name"])]


def main() -> int:
    bodies = blocks(committed())
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        new = filled(text, bodies)
        if new != text:
            atomic_write(page, lambda temporary, new=new: Path(temporary).write_text(new, encoding="utf-8"))
            print(f"wrote {page.relative_to(ROOT)}: {', '.join(m['name'] for m in BLOCK.finditer(new))}")
    return 0
