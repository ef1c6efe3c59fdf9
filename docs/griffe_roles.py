"""A griffe extension for the API reference: the docstrings' reStructuredText roles as links.

The docstrings cross-reference in Sphinx's roles (``:class:`Bloom```, ``:func:`~torchgrade.bloom.bloom```,
``:mod:`.prefilter```), which mkdocstrings' Google-style parser leaves as literal text. Each role becomes an
optional cross-reference of mkdocs-autorefs: a link to the object's entry where the reference renders it, its name
in code where it does not (a private helper, a name from another library). A ``~`` shows the last part of the name
only, as in Sphinx. Names resolve as Python would from the docstring's object: relative to its package with leading
dots, through its module's names and imports otherwise.
"""

from __future__ import annotations

import html
import re

import griffe

ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj|const):`(?P<short>~?)(?P<target>[^`]+)`")
"""A Sphinx role in a docstring; ``short`` is its ``~``."""


def resolved(obj: griffe.Object, target: str) -> str | None:
    """The full path ``target`` names from ``obj``'s scope, or ``None`` where it cannot be told."""
    module = obj if obj.is_module else obj.module
    if target.startswith("."):
        dots = len(target) - len(target.lstrip("."))
        package = module.path.split(".")
        base = package[: len(package) - dots + (1 if module.is_init_module else 0)]
        return ".".join(base + [target[dots:]]) if target[dots:] else ".".join(base)
    head, _, rest = target.partition(".")
    for scope in (obj, module):
        try:
            path = scope.resolve(head)
        except (griffe.NameResolutionError, AttributeError):
            continue
        return f"{path}.{rest}" if rest else path
    return target if target.startswith("torchgrade.") else None


def link(obj: griffe.Object, match: re.Match) -> str:
    """The autorefs tag for one role: ``<autoref identifier=... optional><code>name</code></autoref>``."""
    target = match["target"].strip()
    shown = target.rsplit(".", 1)[-1] if match["short"] else target.lstrip(".")
    path = resolved(obj, target)
    code = f"<code>{html.escape(shown)}</code>"
    if path is None:
        return code
    return f'<autoref identifier="{html.escape(path)}" optional>{code}</autoref>'


class SphinxRoles(griffe.Extension):
    """Rewrites every docstring's roles as it is loaded (:func:`link`)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None and ":" in obj.docstring.value:
            obj.docstring.value = ROLE.sub(lambda match: link(obj, match), obj.docstring.value)
