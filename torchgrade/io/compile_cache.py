"""Compiled graphs saved to a file and loaded in another process: PyTorch's cache artifacts
(``torch.compiler.save_cache_artifacts``), which hold Inductor's generated code and AOTAutograd's graphs for what this
process compiled, so that a compile of the same look on another machine of the same kind (same torch, same device)
skips code generation.

Examples:
    >>> import pathlib, tempfile, torch, torchgrade as tg
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "look.compiled"
    >>> compiled = tg.compile(tg.ToneMap("reinhard"))
    >>> _ = compiled.warm_up(torch.rand(1, 3, 8, 8))  # doctest: +SKIP
    >>> save_compile_cache(path)  # doctest: +SKIP
    >>> load_compile_cache(path)  # in the next process, before its first compile  # doctest: +SKIP
    True
"""

from __future__ import annotations

import warnings
from pathlib import Path

import torch

from ..base.files import read_regular
from .atomic import atomic_write

__all__ = ["save_compile_cache", "load_compile_cache", "MAX_CACHE_BYTES"]

MAX_CACHE_BYTES = 1 << 30
"""Largest cache file :func:`load_compile_cache` reads (the cinematic look's is about 3 MB)."""


def save_compile_cache(path) -> bool:
    """Write what this process compiled to ``path``, atomically: ``False`` (and no file) where it compiled nothing."""
    saved = torch.compiler.save_cache_artifacts()
    if saved is None:
        return False
    data, _ = saved
    atomic_write(path, lambda temporary: Path(temporary).write_bytes(data))
    return True


def load_compile_cache(path) -> bool:
    """Load a file :func:`save_compile_cache` wrote, before the first compile: ``True`` if PyTorch took it.

    A missing file, a pipe or a file over :data:`MAX_CACHE_BYTES` is refused (``FileNotFoundError``, ``ValueError``);
    artifacts PyTorch cannot use (another torch, a damaged file) warn and load nothing: the compile then runs cold.
    """
    data = read_regular(path, MAX_CACHE_BYTES, "compile cache")
    try:
        loaded = torch.compiler.load_cache_artifacts(data)
    except Exception as error:  # torch's own checks of the artifacts (versions, format), where it raises them
        loaded, reason = None, f" ({error})"
    else:
        reason = ""
    if loaded is None:
        warnings.warn(f"{path}: PyTorch could not load the compile cache{reason} (written by another torch, or "
                      "damaged); compiles run without it", RuntimeWarning, stacklevel=2)
        return False
    return True
