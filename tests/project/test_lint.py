"""The code passes the linter ``pyproject.toml`` configures (``[tool.ruff]``: pyflakes, pycodestyle's errors and
warnings, bugbear), run as a user runs it after ``make setup``."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LINTED = ("torchgrade", "tests", "benchmarks", "examples", "docs", "setup.py")
"""Every Python file of the project: the package, its tests, benchmarks, examples, the documentation's scripts."""


def test_ruff_finds_nothing_in_the_package_tests_benchmarks_and_examples():
    selected = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["ruff"]["lint"]["select"]
    assert {"E", "W", "F", "B"} <= set(selected), selected
    command = [sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", *LINTED]
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]
