"""The package's structure: the maths modules ask no context question (the runtime does: per device, the strips of
a per-pixel stage and the checks of values), state passes as arguments, and the packages import one another without a
cycle."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "torchgrade"

QUESTIONS = ("is_exporting", "is_tracing", "policy_for", "untracked", "is_compiling", "is_differentiated", "readable",
             "pixel_layout", "check_eagerly", "in_strips", "sizes_are_symbolic", "nonnegative")
"""Calls that ask where a call runs (exporting, tracing, compiling, which device, whether a gradient is recorded), or
run a step only in some of those places: the predicates and the helpers that ask them for their caller."""
RUNTIME_PACKAGES = ("runtime", "onnx")
"""The packages whose job is to answer them."""
PENDING = {"lut/apply.py": 3, "lut/layer.py": 1}
"""The LUT lookup's questions, left to its operator's next step: whether the operator runs (on the CPU, its kernel's
device, outside forward-mode derivatives, which it has no formula for: ``runs_operator``), whether the lookup off the
CPU takes its whole-frame form (where nothing records: ``whole_frame_tables``), and whether the table's planar rows
are cached (not while compiling: ``LUT3D.rows``)."""


def calls_of(names, keyword=None) -> list:
    """``path:line name`` of every call of one of ``names`` outside :data:`RUNTIME_PACKAGES` (with ``keyword``: only
    calls that pass it)."""
    calls = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.relative_to(PACKAGE).parts[0] in RUNTIME_PACKAGES:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", None)
                if name in names and (keyword is None or any(k.arg == keyword for k in node.keywords)):
                    calls.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {name}")
    return calls


def test_the_maths_modules_ask_no_context_question():
    """Every formula has one form, the same eager, under autograd, compiled and exported: no module outside the
    runtime asks where it runs, directly or through a helper, but the LUT's lookup (:data:`PENDING`)."""
    calls = calls_of(QUESTIONS)
    by_file = {}
    for call in calls:
        by_file[call.split(":")[0]] = by_file.get(call.split(":")[0], 0) + 1
    assert by_file == PENDING, "\n".join(calls)


def test_constants_are_placed_by_their_callers_and_the_non_finite_policy_asks_nothing():
    """``folded`` keeps a constant where its caller says (``host``, a bool), never where autograd happens to record;
    ``sanitize`` takes the caller's word that a frame holds no NaN (``nan_free``) wherever it runs."""
    hosts = [node for path in PACKAGE.rglob("*.py") for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) == "folded"
             for keyword in node.keywords if keyword.arg == "host" and not isinstance(getattr(keyword.value, "value", None), bool)]
    assert hosts == []
    source = (PACKAGE / "base" / "images.py").read_text()
    sanitize = next(node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.FunctionDef) and node.name == "sanitize")
    asked = [node.func.id for node in ast.walk(sanitize) if isinstance(node, ast.Call) and getattr(node.func, "id", None) in QUESTIONS]
    assert asked == []


def test_no_formula_has_a_second_form_by_context():
    """No variant registry (``runtime/variants.py``) and no ``@reference.variant(context)`` forms: a second form of a
    formula is a registered operator's kernel (``torch.library``) or an export rule (``torchgrade/onnx/symbolics.py``)."""
    assert not (PACKAGE / "runtime" / "variants.py").exists()
    declared = [f"{path.relative_to(PACKAGE)}:{node.lineno}" for path in PACKAGE.rglob("*.py")
                for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.Attribute) and node.attr == "variant"]
    assert declared == []


def test_state_is_passed_not_read_from_signatures():
    """Whether a module takes ``nan_free`` (or anything else) is declared (``takes_nan_free``), never read from its
    ``forward``'s signature."""
    readers = [f"{path.relative_to(PACKAGE)}:{node.lineno}" for path in PACKAGE.rglob("*.py")
               for node in ast.walk(ast.parse(path.read_text()))
               if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "signature"
               and any(isinstance(arg, ast.Attribute) and arg.attr == "forward" for arg in node.args)]
    assert readers == []


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
