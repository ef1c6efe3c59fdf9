"""The suite's committed results and the pages that quote them: a fresh run of the quick form's accuracy (nothing
timed) gives the committed accuracy columns, every committed run names its commit and command, and every figure the
pages quote is what ``python -m benchmarks suite --pages`` writes from the results."""

from __future__ import annotations

import re
import sys
import tempfile
import warnings
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchgrade as tg  # noqa: E402
from benchmarks.common import ROOT  # noqa: E402
from benchmarks.suite import forms, measure, pages  # noqa: E402
from benchmarks.suite.workload import Plan, Workload  # noqa: E402
from torchgrade.lut import operator  # noqa: E402

COMMITTED = pages.committed()
ACCURACY = {"p999_error_8bit": 0.005, "max_error_8bit": 0.005, "mean_delta_e2000": 0.0005}
"""Each accuracy column and half its last shown digit (the tables show codes to 0.01 and ΔE2000 to 0.001): a fresh
figure may differ from the committed one by float rounding, never by a shown digit."""


@pytest.fixture(scope="module")
def fresh_quick_rows():
    """Every row of the quick form built and its accuracy measured now, by name (as ``--quick`` measures it)."""
    with tempfile.TemporaryDirectory() as folder, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.manual_seed(0)
        work = Workload(Plan.of(quick=True), Path(folder))
        _, records = measure.measure_rows(work)
    return work, {record["method"]: record for record in records}


def test_the_quick_form_is_committed():
    assert "quick" in COMMITTED, "run: .venv/bin/python -m benchmarks suite --committed"


def test_a_fresh_quick_run_reproduces_the_committed_accuracy_columns(fresh_quick_rows):
    work, fresh = fresh_quick_rows
    committed = COMMITTED["quick"]
    assert {name: list(image.shape[-2:]) for name, image in work.scenes.items()} == committed["accuracy_sizes"]
    assert list(fresh) == [row["method"] for row in committed["rows"]]
    for row in committed["rows"]:
        now = fresh[row["method"]]
        assert now.get("error") == row.get("error"), row["method"]
        for column, rounding in ACCURACY.items():
            assert now.get(column) == pytest.approx(row.get(column), abs=rounding), (row["method"], column)


def test_the_quick_form_has_a_row_for_every_method_a_user_picks(fresh_quick_rows):
    _, fresh = fresh_quick_rows
    families = {record["family"] for record in fresh.values()}
    assert {"direct", "lut", "onnxruntime", "openvino", "opencolorio"} <= families
    assert {record["dtype"] for record in fresh.values()} >= {"float32", "float16", "bfloat16"}
    default = [record for record in fresh.values() if record.get("default_bake") and record["timed"] == "per-pixel stage"
               and record["family"] == "lut"]
    assert {r["interpolation"] for r in default} == {"tetrahedral", "trilinear"}
    assert {r.get("lookup_form") for r in default if r["interpolation"] == "tetrahedral"} == {
        forms.TORCH_FORM, forms.COMPILED_LOOP if forms.compiled_loop_runs("tetrahedral") else
        f"{forms.TORCH_FORM}: the loop did not compile here"}
    assert any(r["family"] == family and r["timed"] == "whole look" for family in ("direct", "lut", "onnxruntime", "openvino")
               for r in fresh.values())


def test_the_default_bake_rows_are_what_the_library_bakes_by_default(fresh_quick_rows):
    """The rows' size and lattice come from the LUT ``bake_lut`` returns with every default, which is the lattice
    ``look.to_lut()`` bakes (the door a user of a whole look takes) at the size documented for it."""
    work, fresh = fresh_quick_rows
    baked = work.baked_look.lut
    assert (baked.size, baked.shaper) == (tg.lut.shapers.DEFAULT_SIZES[baked.shaper], baked.shaper)
    default = [record for record in fresh.values() if record.get("default_bake")]
    assert default and all((r["lut_size"], r["shaper"]) == (baked.size, baked.shaper) for r in default)


@pytest.mark.parametrize("form", sorted(COMMITTED))
def test_every_committed_run_names_its_commit_and_command(form):
    results = COMMITTED[form]
    assert re.fullmatch(r"[0-9a-f]{40}", results["commit"]) and isinstance(results["modified"], bool)
    assert results["command"].endswith(f"--out benchmarks/results/suite/{form}") and results["quick"] == (form == "quick")
    assert ("--quick" in results["command"]) == results["quick"]
    assert results["wall_s"] > 0 and results["cpu_s"] > 0 and results["environment"]["cpu_count"] >= 1


@pytest.mark.parametrize("page", pages.PAGES, ids=lambda page: page.name)
def test_the_pages_quote_the_committed_results(page):
    """Every marked block is what ``python -m benchmarks suite --pages`` writes from the committed results."""
    bodies = pages.blocks(COMMITTED)
    names = [match["name"] for match in pages.BLOCK.finditer(page.read_text(encoding="utf-8"))]
    assert names and pages.stale(page, bodies) == [], "run: .venv/bin/python -m benchmarks suite --pages"


SUITE_FIGURES = re.compile(r"ms/MP|× OCIO")
"""How the suite's figures read on a page."""


def test_no_page_quotes_the_suite_outside_its_blocks():
    quoted = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        outside = pages.BLOCK.sub("", page.read_text(encoding="utf-8"))
        quoted += [f"{page.name}: {line.strip()[:80]}" for line in outside.splitlines() if SUITE_FIGURES.search(line)]
    assert quoted == []


def test_filled_rewrites_the_blocks_and_nothing_else():
    text = "before\n<!-- suite:a -->\nold 1.0 ms/MP\n<!-- /suite:a -->\nafter 2.0\n"
    assert pages.filled(text, {"a": "new\n"}) == "before\n<!-- suite:a -->\nnew\n<!-- /suite:a -->\nafter 2.0\n"
    with pytest.raises(ValueError, match="no suite block named 'a'"):
        pages.filled(text, {"b": ""})


def test_the_torch_form_leaves_the_compiled_loop_out_and_gives_its_values(monkeypatch):
    calls = []
    built = operator.NATIVE

    class CountedLoop:
        def interpolate(self, *args):
            calls.append(1)
            return built.interpolate(*args)

    counted = None if built is None else CountedLoop()
    monkeypatch.setattr(operator, "NATIVE", counted)
    lut = tg.LUT3D(torch.rand(9, 9, 9, 3, generator=torch.Generator().manual_seed(0)), shaper="logc")
    image = torch.rand(1, 3, 32, 48, generator=torch.Generator().manual_seed(1)) * 4
    with torch.no_grad():
        with forms.lookup_form(forms.COMPILED_LOOP):
            looped = lut(image)
        loop_calls = len(calls)
        with forms.lookup_form(forms.TORCH_FORM):
            torch_form = lut(image)
    assert len(calls) == loop_calls and (loop_calls > 0) == forms.compiled_loop_runs("tetrahedral")
    assert operator.NATIVE is counted  # restored after the block
    torch.testing.assert_close(torch_form, looped, rtol=1e-5, atol=1e-6)
