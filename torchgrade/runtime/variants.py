"""One formula, one differentiable reference, and the other forms a context needs, declared beside it.

A maths module writes each formula once, differentiable, and marks it :func:`formula`. Where a context needs another
form of it, the module declares that form beside the reference with ``@reference.variant(CONTEXT)``; calling the
formula then runs the form of the first context that holds (in the order of :data:`CONTEXTS`, and only where the
variant's ``when`` accepts the arguments), the reference otherwise. The maths modules ask no context question
themselves: the runtime answers it here, once, for every formula.

The contexts:

* ``"export"``: an ONNX export is recording (:func:`~torchgrade.runtime.recording.is_exporting`). Forms whose graph
  onnxruntime runs faster (a ``Log`` and an ``Exp`` for a ``Pow``, clamps for a comparison and a ``Where``;
  ``benchmarks/results/onnx_ops.md``); no gradient.
* ``"graph"``: a graph is recorded, by an exporter, a tracer or a compiler
  (:func:`~torchgrade.runtime.recording.is_tracing`). Forms made of operations every such graph holds (an ONNX
  export has no search, for one).
* ``"untracked"``: eager, nothing records a graph and no tensor argument needs a gradient
  (:func:`~torchgrade.runtime.recording.untracked`). Forms that write their own temporaries in place and take fewer
  passes; no gradient.
* ``"planes"``: the device's policy computes per-pixel chains on the image's three planes
  (:attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`: while compiling), which Inductor fuses into one kernel.
  Differentiable: their gradients are held to the reference's too.
* ``"kernels"``: the device's policy runs filters as library kernels, one launch each
  (:attr:`~torchgrade.runtime.ExecutionPolicy.filters_as_kernels`: a GPU, eager).
* ``"host"``: eager on the CPU, where the policy reads values: the views and slices the CPU is fastest at.
* ``"sizes"``: sizes are Python numbers (eager, or compiling; not while a graph is traced for ONNX,
  :func:`~torchgrade.runtime.recording.sizes_are_symbolic`): forms for particular sizes (even sides, exact doubling).

Every variant is held to its reference by one test over :data:`FORMULAS` (``tests/runtime/test_variants.py``: edge
values, the dtypes each formula is reached with, gradients of the planes forms).

Examples:
    >>> import torch
    >>> @formula
    ... def double(x):
    ...     return x * 2
    >>> @double.variant("untracked")
    ... def _double_in_place(x):
    ...     return x.clone().mul_(2)
    >>> double(torch.ones(2)).tolist(), double(torch.ones(2, requires_grad=True)).requires_grad
    ([2.0, 2.0], True)
    >>> del FORMULAS[double.formula.name]
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable, Optional

import torch

from .policy import policy_for
from .recording import is_exporting, is_tracing, sizes_are_symbolic, untracked

__all__ = ["formula", "Formula", "Variant", "FORMULAS", "CONTEXTS"]

CONTEXTS = {"export": lambda tensors: is_exporting(), "graph": lambda tensors: is_tracing(),
            "untracked": lambda tensors: untracked(*tensors),
            "planes": lambda tensors: bool(tensors) and policy_for(tensors[0].device).pixel_planes,
            "kernels": lambda tensors: bool(tensors) and policy_for(tensors[0].device).filters_as_kernels,
            "host": lambda tensors: bool(tensors) and policy_for(tensors[0].device).reads_values,
            "sizes": lambda tensors: not sizes_are_symbolic()}
"""The contexts a variant may be declared for, each with whether it holds for a call's tensor arguments, in the order
they are tried."""


@dataclass(frozen=True)
class Variant:
    """A form of a formula for one context: ``function`` takes the reference's arguments; ``when`` (the same
    arguments) says whether it applies to them, ``None`` always."""

    context: str
    function: Callable
    when: Optional[Callable] = None


@dataclass
class Formula:
    """A reference and its variants by context (:func:`formula` makes one and registers it in :data:`FORMULAS`)."""

    name: str
    reference: Callable
    variants: dict = field(default_factory=dict)

    def variant(self, context: str, when: Optional[Callable] = None) -> Callable:
        """Declare the decorated function as this formula's form for ``context`` (see :data:`CONTEXTS`)."""
        if context not in CONTEXTS:
            raise ValueError(f"context must be one of {', '.join(map(repr, CONTEXTS))}, got {context!r}")

        def declare(function: Callable) -> Callable:
            self.variants[context] = Variant(context, function, when)
            return function

        return declare

    def form(self, args: tuple, kwargs: dict) -> Callable:
        """The function a call with these arguments runs: the first variant whose context holds for the call's tensors
        (its tensor arguments, and those of its tuple and list arguments) and which applies."""
        tensors = [tensor for value in (*args, *kwargs.values()) for tensor in _tensors_in(value)]
        for context, holds in CONTEXTS.items():
            variant = self.variants.get(context)
            if variant is not None and holds(tensors) and (variant.when is None or variant.when(*args, **kwargs)):
                return variant.function
        return self.reference


def _tensors_in(value) -> tuple:
    """The tensors an argument holds: itself, or those of a tuple or list (an image's planes)."""
    if isinstance(value, torch.Tensor):
        return (value,)
    if isinstance(value, (tuple, list)):
        return tuple(item for item in value if isinstance(item, torch.Tensor))
    return ()


FORMULAS: dict = {}
"""Every formula with its variants, by ``module.name``."""


def formula(reference: Callable) -> Callable:
    """Mark ``reference`` as a formula: the returned function runs the form the context needs (a declared variant, or
    ``reference``), and carries ``.variant`` to declare forms and ``.formula`` (its :class:`Formula`)."""
    entry = Formula(f"{reference.__module__}.{reference.__qualname__}", reference)
    FORMULAS[entry.name] = entry

    @functools.wraps(reference)
    def run(*args, **kwargs):
        if not entry.variants:
            return reference(*args, **kwargs)
        return entry.form(args, kwargs)(*args, **kwargs)

    run.variant = entry.variant
    run.formula = entry
    return run
