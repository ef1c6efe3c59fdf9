"""Seeded fuzzing of everything torchgrade reads or writes from outside: EXR headers and chunk tables, ``.cube``
files, CLF writes and look configs (``benchmarks/fuzz.py``). Every mutation is refused with ``ValueError`` or
accepted with finite results: no other exception, crash or hang. ``benchmarks/robustness.py --fuzz`` runs the long
version and commits its counts."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.fuzz import DEFECTS_FREE, FAMILIES  # noqa: E402

COUNTS = {"exr": 200, "cube": 100, "clf": 300, "config": 300}
"""Mutations a suite run tries per family (about a minute together here)."""


@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_mutation_is_refused_with_value_error_or_accepted_finite(family):
    verdicts = FAMILIES[family](COUNTS[family], seed=0)
    assert sum(verdicts.values()) >= COUNTS[family]
    defects = {verdict: n for verdict, n in verdicts.items() if verdict not in DEFECTS_FREE}
    assert not defects, f"{family}: {dict(verdicts)}"
    assert verdicts["refused"] and verdicts["accepted"], f"{family}: the mutations should reach both verdicts, {dict(verdicts)}"
