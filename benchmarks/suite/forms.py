"""The two CPU forms of a LUT lookup the suite times side by side: the compiled loop and the torch form.

On the CPU, without autograd, :class:`torchgrade.LUT3D` looks a frame up through its interpolation's compiled loop
where the loop compiled here (``torchgrade/lut/lookup.c``), else through its torch form (what a machine without a C
compiler runs, or a process started with ``TORCHGRADE_NATIVE=0``). The environment variable switches a whole
process; the suite times both forms in one session, so it takes the loop out of the library's public registry of
interpolations (:data:`torchgrade.lut.KERNELS`, each :class:`~torchgrade.lut.Kernel`'s ``compiled`` field) for the
duration of a call. :func:`lookup_form` is the one place that knows how a form is chosen. Part of
``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

import contextlib
import dataclasses

import torch

from torchgrade.lut import KERNELS

__all__ = ["COMPILED_LOOP", "TORCH_FORM", "FORMS", "lookup_form", "compiled_loop_runs"]

COMPILED_LOOP, TORCH_FORM = "compiled loop", "torch form"
FORMS = (COMPILED_LOOP, TORCH_FORM)
"""The CPU lookup forms, as the rows name them."""


@contextlib.contextmanager
def lookup_form(form: str):
    """Within the block, CPU LUT lookups run in ``form``: :data:`COMPILED_LOOP` (the library's own choice: the loop
    where it compiled) or :data:`TORCH_FORM` (every interpolation without its compiled loop).

    Examples:
        >>> with lookup_form(TORCH_FORM):
        ...     KERNELS["tetrahedral"].compiled is None
        True
    """
    if form not in FORMS:
        raise ValueError(f"lookup form must be one of {FORMS}, got {form!r}")
    kept = dict(KERNELS)
    if form == TORCH_FORM:
        KERNELS.update({name: dataclasses.replace(kernel, compiled=None) for name, kernel in kept.items()})
    try:
        yield
    finally:
        KERNELS.update(kept)


def compiled_loop_runs(interpolation: str) -> bool:
    """Whether :data:`COMPILED_LOOP` lookups with ``interpolation`` run the loop here (it compiled), rather than the
    torch form."""
    compiled = KERNELS[interpolation].compiled
    return compiled is not None and compiled(torch.float32) is not None
