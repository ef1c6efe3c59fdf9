"""The committed results of ``python -m benchmarks lut_footage`` and the page that quotes them: the run names its
commit and command and the lattice it baked, its tables are what the benchmark writes from its own records, a fresh
bake gives its figures, and docs/lut.md quotes them only through ``python -m benchmarks suite --pages``, its reading of
them holding."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchgrade as tg  # noqa: E402
from benchmarks import lut_footage  # noqa: E402
from benchmarks.common import ROOT, environment_line, sample_exr  # noqa: E402
from benchmarks.suite import pages  # noqa: E402
from torchgrade.lut.shapers import SHAPERS  # noqa: E402

COMMITTED = pages.marked_results(pages.LUT_FOOTAGE, "lut")
REPORT = COMMITTED["report"]
PAGE = ROOT / "docs" / "lut.md"
SHOWN = 0.005
"""Half the last digit the tables show (codes to 0.01): a fresh figure may differ by float rounding, never by a digit."""
KINK = "a kink within a cell"
SIZE = "size"


def ratios(look: dict) -> list:
    return [(row["figure"], row["report"] / row["real"]) for row in look["rows"]]


def test_the_run_names_its_commit_and_command():
    assert re.fullmatch(r"[0-9a-f]{40}", REPORT["commit"]) and REPORT["modified"] is False
    assert REPORT["command"] == f"{lut_footage.COMMAND} --out benchmarks/results"
    assert f"Made by `{REPORT['command']}` at commit `{REPORT['commit'][:7]}`" in pages.LUT_FOOTAGE.with_suffix(".md").read_text()


def test_every_look_was_baked_as_bake_lut_bakes_by_default():
    size = SHAPERS["logc_extended"].default_size
    assert REPORT["lattice"] == f"`logc_extended` {size}³, tetrahedral"
    assert list(REPORT["looks"]) == list(lut_footage.LOOKS)


def test_the_committed_page_is_what_the_benchmark_writes_from_its_records():
    """The whole ``.md``, its marked tables included, from the ``.json`` beside it."""
    written = "\n".join([*lut_footage.markdown(REPORT), "", environment_line(REPORT["environment"])]) + "\n"
    assert pages.LUT_FOOTAGE.with_suffix(".md").read_text(encoding="utf-8") == written
    assert set(COMMITTED["tables"]) == set(pages.LUT_TABLES.values())


def test_the_docs_quote_the_committed_results():
    """docs/lut.md holds every block that quotes the benchmark, each as ``suite --pages`` writes it."""
    names = {match["name"] for match in pages.BLOCK.finditer(PAGE.read_text(encoding="utf-8"))}
    assert names == set(pages.LUT_TABLES)
    assert pages.stale(PAGE, pages.quoted_blocks(pages.LUT_FOOTAGE, "lut", pages.LUT_TABLES)) == [], "run: .venv/bin/python -m benchmarks suite --pages"


def test_where_the_report_names_size_no_figure_understates_by_more_than_2x_and_only_photographs_are_overstated():
    """docs/lut.md's reading: on every look whose report names size as its cause, report / real is at least 1/2 on
    every picture, and above 2 only for the realistic figure on a photograph."""
    sized = {label: look for label, look in REPORT["looks"].items() if look["cause"].split(" (")[0] == SIZE}
    assert len(sized) == 4
    for label, look in sized.items():
        assert [(figure, ratio) for figure, ratio in ratios(look) if ratio < 0.5] == [], label
        assert {figure for figure, ratio in ratios(look) if ratio > 2.0} <= {"realistic colours"}, label


def test_the_one_look_outside_says_it_bends_within_a_cell_and_to_apply_it_directly():
    outside = {label: look for label, look in REPORT["looks"].items() if look["cause"].split(" (")[0] != SIZE}
    assert list(outside) == ["contrast 15, saturation 10, Neutral"]
    look = outside["contrast 15, saturation 10, Neutral"]
    assert look["cause"].startswith(KINK) and "apply the transform directly" in look["report"]
    found = [ratio for _, ratio in ratios(look)]
    assert min(found) < 0.5 and max(found) > 2.0  # "its figures miss both ways"


def test_with_frames_the_report_is_every_pixels():
    """The ``frames=`` table: every pixel of each image counted, and the report's p99.9 and max are the real ones (its
    errors are kept in float32 for the quantile: 6e-8 relative)."""
    for row in REPORT["frames"]:
        image = sample_exr(row["image"])
        assert row["pixels"] == image.shape[-2] * image.shape[-1], row["image"]
        assert row["report_p99_9"] == pytest.approx(row["real_p99_9"], rel=1e-6, abs=1e-6), row["image"]
        assert row["report_max"] == pytest.approx(row["real_max"], abs=1e-9), row["image"]


def test_a_fresh_bake_gives_the_committed_figures(monkeypatch):
    """The README look's default bake now: its report, and the real p99.9 on one photograph, both charts and the
    three still lifes, as committed."""
    label = "README Python: contrast 20, saturation 10, ACES"
    monkeypatch.setattr(lut_footage, "PHOTOGRAPHS", ("Garden",))
    _, rows = lut_footage.footage_rows(tg.PostFX.from_config(lut_footage.LOOKS[label]).eval())
    committed = {(row["figure"], row["picture"]): row for row in REPORT["looks"][label]["rows"]}
    assert len(rows) == 6
    for row in rows:
        expected = committed[row["figure"], row["picture"]]
        for figure in ("report", "real"):
            assert row[figure] == pytest.approx(expected[figure], abs=SHOWN), (row["figure"], row["picture"], figure)
