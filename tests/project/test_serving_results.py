"""The committed results of ``python -m benchmarks serving``: the run names its commit and command, its page is what the
benchmark writes from its own records, docs/onnx.md quotes its table only through ``python -m benchmarks suite
--pages``, and what it measured is what the issue of a public endpoint asks: every real frame graded, the replica under
its memory budget, a normal client answered within 5 s while 24 connections trickle bodies, each trickler refused."""

from __future__ import annotations

import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks import bench_serving  # noqa: E402
from benchmarks.common import ROOT, environment_line  # noqa: E402
from benchmarks.suite import pages  # noqa: E402

COMMITTED = pages.marked_results(pages.SERVING, "serving")
REPORT = COMMITTED["report"]


def test_the_run_names_its_commit_and_command():
    assert re.fullmatch(r"[0-9a-f]{40}", REPORT["commit"]) and REPORT["modified"] is False
    assert REPORT["command"].startswith(".venv/bin/python -m benchmarks serving --requests ") and not REPORT["quick"]
    assert REPORT["command"].endswith("--out benchmarks/results")


def test_the_committed_page_is_what_the_benchmark_writes_from_its_records():
    written = "\n".join([*bench_serving.markdown(REPORT), "", environment_line(REPORT["environment"])]) + "\n"
    assert pages.SERVING.with_suffix(".md").read_text(encoding="utf-8") == written
    assert set(COMMITTED["tables"]) == set(pages.SERVING_TABLES.values())


def test_every_frame_was_graded_within_the_budget_and_slow_clients_starved_no_one():
    real, slow = REPORT["real_frames"], REPORT["slow_clients"]
    assert real["statuses"] == {"200": real["requests"]} and real["concurrency"] == bench_serving.CLIENTS
    assert real["server"]["peak_rss_mib"] <= REPORT["memory_mib"]
    assert slow["statuses"] == {"200": slow["requests"]} and slow["latency_ms_max"] < 5000.0
    assert set(slow["slow_answers"]) == {"408"}


def test_the_onnx_page_quotes_the_table():
    page = ROOT / "docs" / "onnx.md"
    blocks = pages.quoted_blocks(pages.SERVING, "serving", pages.SERVING_TABLES)
    assert set(blocks) <= {match["name"] for match in pages.BLOCK.finditer(page.read_text(encoding="utf-8"))}
    assert not set(pages.stale(page, blocks)) & set(blocks), "run: .venv/bin/python -m benchmarks suite --pages"
