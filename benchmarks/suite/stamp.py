"""What a run of the suite records about itself: the commit it measured and the CPU time it took. Part of
``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

import resource
import subprocess

from benchmarks.common import ROOT

__all__ = ["MEASURED_PATHS", "source_commit", "cpu_seconds"]

MEASURED_PATHS = ("torchgrade", "benchmarks", ":(exclude)benchmarks/results", "pyproject.toml")
"""The files whose changes change what the suite measures (not its results, not the pages written from them)."""


def _git(*arguments: str) -> str:
    done = subprocess.run(["git", "-C", str(ROOT), *arguments], capture_output=True, text=True)
    return done.stdout.strip() if done.returncode == 0 else ""


def source_commit() -> dict:
    """``{"commit": sha, "modified": bool}``: the checkout's commit, and whether :data:`MEASURED_PATHS` differ from it
    (a run of uncommitted code; ``commit`` is ``None`` outside a git checkout)."""
    commit = _git("rev-parse", "HEAD") or None
    changed = _git("status", "--porcelain", "--untracked-files=no", "--", *MEASURED_PATHS) if commit else ""
    return {"commit": commit, "modified": bool(changed)}


def cpu_seconds() -> float:
    """CPU seconds (user + system) this process and its finished children have used."""
    own, children = (resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime
