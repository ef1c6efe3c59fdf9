"""Range checks of learnable controls on a GPU, without waiting for it.

A learnable control is checked against its range before every forward (an optimiser may have moved it out).
On the CPU the check reads the value directly. On CUDA a read would wait for every queued kernel, once per
frame; instead :class:`DeferredCheck` copies a value to pinned host memory without blocking when its version
changes (an optimiser step changes it in place), and checks the copy at a later forward, once the copy has
landed. A value an optimiser moved out of its range therefore raises at the forward after the one that first
used it (usually the next one), with the same message, and no forward waits for the GPU.

Examples:
    >>> import torch
    >>> seen = []
    >>> check = DeferredCheck()
    >>> check({"gain": torch.tensor(2.0)}, lambda name, value: seen.append((name, value.item())))
    >>> seen  # on the CPU: checked at once
    [('gain', 2.0)]
"""

from __future__ import annotations

from typing import Callable, Optional

import torch

__all__ = ["DeferredCheck"]


class DeferredCheck:
    """Checks ``check(name, value)`` of a stage's learnable values: at once on the CPU, asynchronously on CUDA,
    once per change of a value (its tensor version), never on ``meta`` (no values)."""

    def __init__(self):
        self._checked: dict = {}  # name -> (tensor, version) last copied or checked
        self._landing: dict = {}  # name -> (pinned host copy, CUDA event after the copy)

    def __call__(self, values: dict, check: Callable[[str, torch.Tensor], None], summary: Optional[Callable] = None) -> None:
        """Check each of ``values`` (by name) whose tensor or version changed: ``check(name, summary(value))``.

        ``summary`` (default: the value itself) reduces a large value to what ``check`` needs (a table to its
        extremes), so only that is copied back.
        """
        for name, (host, landed) in list(self._landing.items()):
            if landed.query():
                del self._landing[name]
                check(name, host)
        for name, value in values.items():
            seen = self._checked.get(name)
            if seen is not None and seen[0] is value and seen[1] == value._version:
                continue
            if value.device.type == "meta":
                continue
            summarised = value.detach() if summary is None else summary(value.detach())
            if value.device.type != "cuda":
                check(name, summarised)
            else:
                host = torch.empty(summarised.shape, dtype=summarised.dtype, pin_memory=True)
                host.copy_(summarised, non_blocking=True)
                landed = torch.cuda.Event()
                landed.record()
                self._landing[name] = (host, landed)
            self._checked[name] = (value, value._version)
