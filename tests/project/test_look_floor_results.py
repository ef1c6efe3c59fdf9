"""The committed results of ``python -m benchmarks look_floor`` and the page that quotes them: the run names its commit
and command and was timed (not ``--counts``), its page is what the benchmark writes from its own records, the
deterministic columns (the eager operations and frames written) are what today's look dispatches, and
docs/performance.md quotes the timed table only through ``python -m benchmarks suite --pages``."""

from __future__ import annotations

import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torch  # noqa: E402

import torchgrade as tg  # noqa: E402
from benchmarks import look_floor  # noqa: E402
from benchmarks.common import ROOT, environment_line  # noqa: E402
from benchmarks.suite import pages  # noqa: E402

COMMITTED = pages.marked_results(pages.LOOK_FLOOR, "floor")
REPORT = COMMITTED["report"]


def test_the_run_names_its_commit_and_command_and_was_timed():
    assert re.fullmatch(r"[0-9a-f]{40}", REPORT["commit"]) and REPORT["modified"] is False
    assert REPORT["command"] == f"{look_floor.COMMAND} --out benchmarks/results"
    assert REPORT["frame"] == list(look_floor.FRAME) and REPORT["threads"] == look_floor.THREADS
    assert set(REPORT["timing"]["rows"]) >= {look_floor.COPY, look_floor.EAGER, look_floor.COMPILED, look_floor.EXPORTED}


def test_the_committed_page_is_what_the_benchmark_writes_from_its_records():
    written = "\n".join([*look_floor.markdown(REPORT), "", environment_line(REPORT["environment"])]) + "\n"
    assert pages.LOOK_FLOOR.with_suffix(".md").read_text(encoding="utf-8") == written
    assert set(COMMITTED["tables"]) == set(pages.FLOOR_TABLES.values())


def test_the_eager_counts_are_what_the_look_dispatches_today():
    """Operations, full-frame results and frames written by a 1080p frame of the look and of each stage, counted again
    on the ``meta`` device: a change to the look's maths that changes them calls for a new run."""
    look = tg.PostFX.from_config(look_floor.LOOK).eval()
    assert look_floor.eager_counts(look, torch.Size((1, 3, *look_floor.FRAME))) == REPORT["eager_counts"]


def test_the_performance_page_quotes_the_timed_table():
    page = ROOT / "docs" / "performance.md"
    blocks = pages.quoted_blocks(pages.LOOK_FLOOR, "floor", pages.FLOOR_TABLES)
    assert set(blocks) <= {match["name"] for match in pages.BLOCK.finditer(page.read_text(encoding="utf-8"))}
    assert not set(pages.stale(page, blocks)) & set(blocks), "run: .venv/bin/python -m benchmarks suite --pages"
