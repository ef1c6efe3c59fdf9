"""The package's structure: the maths modules ask no context question (the runtime does, through the variants each
formula declares), state passes as arguments, and the packages import one another without a cycle."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "torchgrade"

PREDICATES = ("is_exporting", "is_tracing", "policy_for", "untracked", "is_compiling")
"""The questions about where a call runs (exporting, tracing, compiling, which device, whether a gradient is recorded)."""
RUNTIME_PACKAGES = ("runtime", "onnx")
"""The packages whose job is to answer them."""
MOST_PREDICATE_CALLS = 14
"""Calls of :data:`PREDICATES` allowed outside :data:`RUNTIME_PACKAGES` (65 before the variants): whether a trusted
input skips the non-finite policy's NaN pass (``base/images.py``, ``look/postfx.py``), whether a control is a known constant
(``base/params.py``), the device policy's sizes for one bloom blur and for resampling matrices, the metering's
histogram tables, the saturation matrix's folding and the LUT's eager-loop choice and table cache. A form of a formula
goes in :mod:`torchgrade.runtime.variants` instead, and this number only goes down."""


def predicate_calls() -> list:
    calls = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.relative_to(PACKAGE).parts[0] in RUNTIME_PACKAGES:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", None)
                if name in PREDICATES:
                    calls.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {name}")
    return calls


def test_the_maths_modules_leave_context_questions_to_the_runtime():
    calls = predicate_calls()
    assert len(calls) <= MOST_PREDICATE_CALLS, "\n".join(calls)


def package_imports() -> dict:
    """``{package: {packages it imports}}`` for the sub-packages of torchgrade (a top-level module counts as one)."""
    graph: dict = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).parts
        source = parts[0].removesuffix(".py")
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level:
                target = _target(parts, node)
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("torchgrade."):
                target = node.module.split(".")[1]
            else:
                continue
            if target and target != source:
                graph.setdefault(source, set()).add(target)
    return graph


def _target(parts: tuple, node: ast.ImportFrom):
    """The top-level package a relative import in the file at ``parts`` reaches, or None for one inside its own."""
    base = list(parts[:-1])[: len(parts) - node.level]
    module = [*base, *(node.module.split(".") if node.module else [])]
    return module[0] if module else (node.names[0].name if node.names else None)


def test_the_packages_import_one_another_without_a_cycle():
    graph = package_imports()
    order, seen, stack = [], set(), []

    def visit(package):
        if package in stack:
            raise AssertionError(f"import cycle: {' -> '.join(stack[stack.index(package):] + [package])}")
        if package in seen:
            return
        stack.append(package)
        for imported in sorted(graph.get(package, ())):
            if imported != "__init__":
                visit(imported)
        stack.pop()
        seen.add(package)
        order.append(package)

    for package in sorted(graph):
        if package != "__init__":
            visit(package)
    assert order.index("runtime") < order.index("base") < order.index("color")


def test_no_module_holds_more_than_450_lines():
    long = {str(path.relative_to(PACKAGE)): n for path in PACKAGE.rglob("*.py")
            if (n := len(path.read_text().splitlines())) > 450}
    assert long == {}


def test_state_passes_as_arguments_not_context_variables():
    """No module keeps call state in a ``ContextVar`` (a trusted frame is ``nan_free=True``, given by the caller)."""
    holders = [str(path.relative_to(PACKAGE)) for path in PACKAGE.rglob("*.py")
               if any(isinstance(node, (ast.Import, ast.ImportFrom)) and "contextvars" in ast.unparse(node)
                      for node in ast.walk(ast.parse(path.read_text())))]
    assert holders == []
