"""Worker threads of one intra-op thread each, for CPU work split into independent pieces (a LUT's pixel runs).

PyTorch's CPU operations release the GIL, so pieces computed in worker threads run on as many cores as there
are workers, and no operation waits at a barrier for the others (each is single-threaded). A worker computes
under the caller's autograd mode (``no_grad`` or ``inference_mode``): callers only split work that nothing
records.

Examples:
    >>> import torch
    >>> out = torch.zeros(4)
    >>> def fill(i):
    ...     out[i] = i * i
    >>> run_pieces(fill, range(4), workers=2)
    >>> out.tolist()
    [0.0, 1.0, 4.0, 9.0]
"""

from __future__ import annotations

import contextlib
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable

import torch

__all__ = ["run_pieces", "worker_pool", "one_thread"]

_POOLS: dict = {}
_LOCK = threading.Lock()


def _forget_pools() -> None:
    """In a child forked from a process with pools: the parent's worker threads do not exist in the child, so a pool
    kept from it would queue pieces that no thread ever runs (the child would wait for them forever)."""
    global _LOCK
    _POOLS.clear()
    _LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):  # where processes fork (not Windows)
    os.register_at_fork(after_in_child=_forget_pools)


def worker_pool(workers: int) -> ThreadPoolExecutor:
    """A pool of ``workers`` threads, each set to one intra-op thread, made once per count.

    ``torch.set_num_threads`` in a thread is that thread's own, but it also sets the count threads started
    later begin with; the caller's count is therefore set again once every worker has started.
    """
    with _LOCK:
        pool = _POOLS.get(workers)
        if pool is None:
            threads = torch.get_num_threads()
            pool = ThreadPoolExecutor(workers, thread_name_prefix="torchgrade-worker", initializer=_one_intra_op_thread)
            started = threading.Barrier(workers + 1)
            for _ in range(workers):
                pool.submit(started.wait)
            started.wait()
            torch.set_num_threads(threads)
            _POOLS[workers] = pool
        return pool


def _one_intra_op_thread() -> None:
    """Set the calling thread to one intra-op thread, for good.

    ATen gives a thread its count lazily, from the process-wide count last set, at the thread's first parallel
    operation or ``get_num_threads``; ``set_num_threads`` does not count as that first use. A worker that only set 1
    took the caller's count back at its first operation (2 on 2 cores, 16 on 16: every worker then ran every
    operation on all the cores at once). Reading the count first makes the thread's own count the one set here.
    """
    torch.get_num_threads()
    torch.set_num_threads(1)


def run_pieces(work: Callable, pieces: Iterable, workers: int) -> None:
    """``work(piece)`` for every piece, on ``workers`` threads (in this thread when ``workers`` is 1).

    Pieces must be independent (each writes its own part of an output). The first exception is raised here
    after every piece has finished.
    """
    pieces = list(pieces)
    if workers <= 1 or len(pieces) <= 1:
        for piece in pieces:
            work(piece)
        return
    mode = torch.inference_mode if torch.is_inference_mode_enabled() else torch.no_grad

    def run(piece):
        with mode():
            work(piece)

    futures = [worker_pool(workers).submit(run, piece) for piece in pieces]
    errors = [future.exception() for future in futures]
    for error in errors:
        if error is not None:
            raise error


@contextlib.contextmanager
def one_thread():
    """Run the block with one intra-op CPU thread, then restore the count (thread-local under OpenMP and MKL).

    Examples:
        >>> import torch
        >>> before = torch.get_num_threads()
        >>> with one_thread():
        ...     torch.get_num_threads()
        1
        >>> torch.get_num_threads() == before
        True
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
