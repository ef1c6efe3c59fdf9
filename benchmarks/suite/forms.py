"""The two CPU forms of a LUT lookup the suite times side by side: the compiled loop and the torch form.

On the CPU :class:`torchgrade.LUT3D` looks a frame up through the operator ``torchgrade::lut_lookup``, whose kernel is
the C loop built with the package (``torchgrade/lut/lookup.c``, :data:`torchgrade.lut.operator.NATIVE`), else its
torch form (what an install built without a C compiler runs). The suite times both forms in one session, so it takes
the built loop out of the operator's module for the duration of a call. :func:`lookup_form` is the one place that
knows how a form is chosen. Part of ``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

import contextlib
import warnings

from torchgrade.lut import operator

__all__ = ["COMPILED_LOOP", "TORCH_FORM", "FORMS", "lookup_form", "compiled_loop_runs"]

COMPILED_LOOP, TORCH_FORM = "compiled loop", "torch form"
FORMS = (COMPILED_LOOP, TORCH_FORM)
"""The CPU lookup forms, as the rows name them."""


@contextlib.contextmanager
def lookup_form(form: str):
    """Within the block, CPU LUT lookups run in ``form``: :data:`COMPILED_LOOP` (the library's own choice: the C loop
    where the package was built with it) or :data:`TORCH_FORM` (the operator's torch form, its warning silenced).

    Examples:
        >>> with lookup_form(TORCH_FORM):
        ...     operator.NATIVE is None
        True
    """
    if form not in FORMS:
        raise ValueError(f"lookup form must be one of {FORMS}, got {form!r}")
    kept = operator.NATIVE
    if form == TORCH_FORM:
        operator.NATIVE = None
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "torchgrade was installed without its compiled LUT loop", RuntimeWarning)
            yield
    finally:
        operator.NATIVE = kept


def compiled_loop_runs(interpolation: str) -> bool:
    """Whether :data:`COMPILED_LOOP` lookups with ``interpolation`` run the C loop here (the package was built with it),
    rather than the torch form."""
    return operator.NATIVE is not None and interpolation in operator.KERNELS
