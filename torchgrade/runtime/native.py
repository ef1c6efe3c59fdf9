"""CPU loops that torch has no single operation for, compiled from C on first use and cached on disk.

A source file beside the module that calls it (such as ``torchgrade/lut/lookup.c``) is compiled by the
system's C compiler (``$CC``, else ``cc``, ``gcc`` or ``clang``: the compiler ``torch.compile`` needs on a CPU too)
into a shared library, once per source, compiler, machine and instruction set, and loaded with :mod:`ctypes` (whose
calls release the GIL). It is built with OpenMP, whose runtime (``libgomp.so.1``) torch has loaded already, so its
parallel loops run on torch's own intra-op threads: the threads a torch operation just before left spinning for work
take it at once, where threads of another pool would compete with them for the cores. The first use costs one
compile (``benchmarks/results/lut_cpu.md`` times it); later processes load the cached library (:func:`cache_folder`;
where none can be made, each process compiles into a private temporary folder). Where no compiler works, or
``TORCHGRADE_NATIVE=0``, :func:`native_library` returns ``None`` (with one warning saying why) and the caller keeps
its torch form. As with torch's own parallel operations, a process forked after a parallel region must use one
thread (``torch.set_num_threads(1)``, as DataLoader workers do): GNU OpenMP's threads do not survive a fork.

The instruction set follows torch's own choice for its CPU kernels (``torch.backends.cpu.get_cpu_capability()``):
AVX2 and FMA where torch uses AVX2 or AVX-512, the compiler's baseline elsewhere, never ``-march=native`` (a cache
folder shared between machines must not hold code that one of them cannot run). No ``-ffast-math``: NaN and
rounding behave as in torch.

Examples:
    >>> from pathlib import Path
    >>> import torchgrade
    >>> library = native_library(Path(torchgrade.__file__).parent / "lut" / "lookup.c")
    >>> library is None or hasattr(library, "tetrahedral_float")
    True
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import os
import platform
import shutil
import stat
import subprocess
import tempfile
import time
import warnings
from pathlib import Path
from typing import Optional

import torch

__all__ = ["native_library", "cache_folder", "compiler_command", "NATIVE_VARIABLE"]

LOG = logging.getLogger("torchgrade.native")

NATIVE_VARIABLE = "TORCHGRADE_NATIVE"
"""Set to ``0`` to keep every lookup in torch operations (no compile, no cached library loaded)."""

CACHE_VARIABLE = "TORCHGRADE_CACHE_DIR"
"""Where compiled libraries are kept: ``$TORCHGRADE_CACHE_DIR``, else ``$XDG_CACHE_HOME/torchgrade``, else
``~/.cache/torchgrade``."""

COMPILE_TIMEOUT_S = 120


def cache_folder() -> Path:
    """The folder compiled libraries are kept in (see :data:`CACHE_VARIABLE`), made private to this user.

    A library is code this process will run, so the folder must be this user's and writable by no one else;
    otherwise ``PermissionError``.

    Examples:
        >>> cache_folder().name
        'native'
    """
    base = os.environ.get(CACHE_VARIABLE) or os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "torchgrade")
    folder = Path(base) / "native"
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    info = folder.stat()
    if hasattr(os, "getuid") and (info.st_uid != os.getuid() or info.st_mode & (stat.S_IWGRP | stat.S_IWOTH)):
        raise PermissionError(f"{folder} belongs to another user or others may write to it: no compiled code is loaded from it")
    return folder


def compiler_command() -> list:
    """The C compiler and flags a library is built with (see the module docstring).

    Examples:
        >>> "-O3" in compiler_command()
        True
    """
    compiler = os.environ.get("CC") or next((found for name in ("cc", "gcc", "clang") if (found := shutil.which(name))), "cc")
    isa = ["-mavx2", "-mfma"] if torch.backends.cpu.get_cpu_capability() in ("AVX2", "AVX512") else []
    return [compiler, "-O3", "-fPIC", "-shared", "-ffp-contract=off", "-fopenmp", *isa]


@functools.lru_cache(maxsize=None)
def native_library(source: Path) -> Optional[ctypes.CDLL]:
    """The shared library of the C file ``source``, compiled on first use and cached (see the module docstring);
    ``None`` where it cannot be had, with a warning saying why."""
    if os.environ.get(NATIVE_VARIABLE, "1") == "0":
        return None
    try:
        return ctypes.CDLL(str(_compiled(Path(source))))
    except (OSError, subprocess.SubprocessError) as error:
        warnings.warn(f"{Path(source).name} could not be compiled ({error}); torchgrade keeps its torch form, which is slower "
                      f"on the CPU (set {NATIVE_VARIABLE}=0 to stop trying)", RuntimeWarning, stacklevel=2)
        return None


def _compiled(source: Path) -> Path:
    """The cached library of ``source``, compiled into a temporary file and moved into place (atomic: processes
    compiling at once each move a whole library)."""
    command = compiler_command()
    version = subprocess.run([command[0], "--version"], capture_output=True, text=True, timeout=COMPILE_TIMEOUT_S).stdout
    text = source.read_bytes()
    key = hashlib.sha256(b"\0".join([text, " ".join(command).encode(), version.encode(), platform.machine().encode()])).hexdigest()
    try:
        folder = cache_folder()
    except PermissionError:
        raise
    except OSError as error:  # no cache folder can be made (a read-only home): a private one for this process
        folder = Path(tempfile.mkdtemp(prefix="torchgrade-native-"))
        LOG.info("no cache folder (%s): compiling into %s", error, folder)
    library = folder / f"{source.stem}-{key[:20]}.so"
    if library.is_file():
        return library
    start = time.perf_counter()
    handle, partial = tempfile.mkstemp(suffix=".so", dir=folder)
    os.close(handle)
    try:
        done = subprocess.run([*command, "-o", partial, str(source)], capture_output=True, text=True, timeout=COMPILE_TIMEOUT_S)
        if done.returncode:
            raise OSError(f"{command[0]} exited with {done.returncode}: {done.stderr.strip()[:500]}")
        os.replace(partial, library)
    finally:
        if os.path.exists(partial):
            os.unlink(partial)
    LOG.info("compiled %s in %.2f s into %s", source.name, time.perf_counter() - start, library)
    return library
