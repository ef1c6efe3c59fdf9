"""The suite's figures on the pages that quote them, written from the committed results and only from them.

    .venv/bin/python -m benchmarks suite --pages

A page marks each generated block ``<!-- suite:NAME -->`` … ``<!-- /suite:NAME -->`` (invisible in rendered
Markdown); :func:`main` rewrites every block of :data:`PAGES` from :data:`COMMITTED` (the full form's results where
they are committed, else the quick form's, and says which), and nothing outside the blocks.
``tests/project/test_suite_results.py`` holds each page to what :func:`filled` would write, and keeps the suite's
figures (``ms/MP``, ``× OCIO``) out of every page but inside its blocks. ``--committed`` (see ``benchmarks/run.py``)
runs both forms and then this.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from benchmarks.common import RESULTS, ROOT
from benchmarks.suite.report import baselines_text, markdown_table, provenance
from benchmarks.suite.runtimes import PEER
from torchgrade.io.atomic import atomic_write

__all__ = ["COMMITTED", "PAGES", "BLOCK", "committed", "blocks", "filled", "stale", "main"]

COMMITTED = {"quick": RESULTS / "suite" / "quick", "full": RESULTS / "suite" / "full"}
"""Where each form's committed results live."""
PAGES = (ROOT / "docs" / "performance.md", ROOT / "README.md")
"""The pages that quote the suite."""
BLOCK = re.compile(r"<!-- suite:(?P<name>[\w-]+) -->\n(?P<body>.*?)<!-- /suite:(?P=name) -->", re.S)
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


RENDERERS = {"look": look_block, "table": table_block, "advice": advice_block, "reproduce": reproduce_block,
             "quick": readme_block}
"""Every block a page may hold, by name."""


def blocks(results: dict) -> dict:
    """The body of every block, from ``results`` (:func:`committed`)."""
    return {name: render(results) for name, render in RENDERERS.items()}


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
