"""Reading a creative CLF LUT: a ``LUT3D`` node, optionally after a ``Range`` onto [0, 1] (the lattice domain) and
before a ``Range`` that clamps (the output range), checked strictly before a table is built.

A CLF file is untrusted XML, read within budgets stated before the cost is paid: only a regular file of at most
:data:`MAX_CLF_BYTES` is opened (a pipe or a device is refused without reading it); the XML is parsed as it streams in,
with no DOCTYPE (so no entity can expand), at most :data:`MAX_CLF_ELEMENTS` elements and :data:`MAX_TEXT_BYTES` of text
outside the table, whose own text may hold at most :data:`BYTES_PER_NUMBER` bytes a number its ``dim`` declares (a
2x2x2 table's 24 numbers: about a kilobyte, whatever the file's size); every number is checked finite and counted
against the ``dim``. An error names what it found, shortened to its first few items.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from xml.parsers import expat

import numpy as np
import torch

from ...base.files import open_regular
from ...lut import LUT3D, MAX_SIZE, MIN_SIZE

__all__ = ["MAX_CLF_BYTES", "MAX_CLF_ELEMENTS", "MAX_TEXT_BYTES", "BYTES_PER_NUMBER", "read_clf"]

MAX_CLF_BYTES = 256 * 2**20
"""Largest CLF file read (256 MiB: a 129³ table at 40 bytes a number); a larger one is refused before parsing."""

MAX_CLF_ELEMENTS = 4096
"""Most XML elements a CLF file may hold: a creative LUT needs about 20."""

MAX_TEXT_BYTES = 1 << 20
"""Most text outside the table's ``Array`` (descriptions, bounds)."""

BYTES_PER_NUMBER = 40
"""Most bytes of an ``Array``'s text per number its ``dim`` declares (a float32 printed in full is 16, with room for
spaces and line ends)."""

_CHUNK_BYTES = 1 << 20
"""Bytes handed to the parser at a time."""

_LISTED = 8
"""Items an error message lists at most."""

_DEPTH_SCALES = {"32f": 1.0, "16f": 1.0, "8i": 255.0, "10i": 1023.0, "12i": 4095.0, "16i": 65535.0}
"""CLF bit depths and the code value of 1.0 in each (SMPTE ST 2136-1, 5.2)."""


def read_clf(path) -> LUT3D:
    """Read a CLF ``ProcessList`` holding one ``LUT3D`` as a :class:`~torchgrade.LUT3D` (its interpolation included).

    A ``Range`` before the table mapping ``[a, b]`` onto [0, 1] becomes the lattice domain; a ``Range`` after it
    whose input and output bounds agree becomes the output clamp. Other process nodes (``Matrix``, ``Log``,
    ``LUT1D``, ...) are refused with their name: apply such files with OpenColorIO. Integer bit depths are
    scaled to [0, 1] (``10i``: codes / 1023). Malformed content raises ``ValueError`` naming the file.

    Examples:
        >>> import tempfile, pathlib
        >>> from torchgrade.io import write_clf
        >>> from torchgrade.lut import LUT3D, identity_table
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     path = pathlib.Path(folder) / "look.clf"
        ...     write_clf(path, LUT3D(identity_table(5) ** 2, interpolation="trilinear"))
        ...     lut = read_clf(path)
        >>> lut.size, lut.interpolation, lut(torch.full((1, 3, 1, 1), 0.5)).flatten().tolist()
        (5, 'trilinear', [0.25, 0.25, 0.25])
    """
    root = _parse(path)
    nodes = [node for node in root if _tag(node) not in ("Description", "InputDescriptor", "OutputDescriptor", "Info")]
    kinds = [_tag(node) for node in nodes]
    if kinds.count("LUT3D") != 1 or any(kind not in ("LUT3D", "Range") for kind in kinds):
        raise ValueError(f"{path}: a creative CLF holds one LUT3D and optional Range nodes, got {_listed(kinds)}; "
                         "apply other CLF files with OpenColorIO")
    at = kinds.index("LUT3D")
    if at > 1 or len(kinds) - at > 2:
        raise ValueError(f"{path}: at most one Range before the LUT3D and one after it, got {_listed(kinds)}")
    domain = _domain(nodes[0], path) if at == 1 else (0.0, 1.0)
    output_range = _clamp(nodes[at + 1], path) if at + 1 < len(nodes) else None
    table, interpolation = _table(nodes[at], path)
    return LUT3D(table, "linear", domain, output_range=output_range, interpolation=interpolation)


def _listed(items: list) -> str:
    """``items`` for an error message: the first :data:`_LISTED` of them, and how many more."""
    if not items:
        return "no nodes"
    shown = ", ".join(items[:_LISTED])
    return f"[{shown}]" if len(items) <= _LISTED else f"[{shown}, ... {len(items) - _LISTED} more]"


def _parse(path) -> ElementTree.Element:
    """The document's root element, built while it streams in within the module's budgets."""
    builder = _BoundedTree(path)
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.StartDoctypeDeclHandler = builder.doctype
    parser.EntityDeclHandler = builder.doctype
    parser.StartElementHandler = builder.start
    parser.EndElementHandler = builder.end
    parser.CharacterDataHandler = builder.data
    with open_regular(path, MAX_CLF_BYTES, "CLF file") as handle:
        try:
            while chunk := handle.read(_CHUNK_BYTES):
                parser.Parse(chunk, False)
            parser.Parse(b"", True)
        except expat.ExpatError as error:
            raise ValueError(f"{path}: not a well-formed CLF file: {error}") from None
    root = builder.tree.close()
    if _tag(root) != "ProcessList":
        raise ValueError(f"{path}: a CLF file's root is ProcessList, got {_tag(root)[:80]}")
    return root


class _BoundedTree:
    """An ``ElementTree.TreeBuilder`` fed by expat that refuses, as it goes, a DOCTYPE, more elements than
    :data:`MAX_CLF_ELEMENTS` and more text than the budgets (the ``Array``'s from its ``dim``)."""

    def __init__(self, path):
        self.path = path
        self.tree = ElementTree.TreeBuilder()
        self.elements = self.text = 0
        self.array_budget = None  # while inside an Array: the bytes of text it may still hold

    def doctype(self, *arguments) -> None:
        raise ValueError(f"{self.path}: a CLF file declares no DOCTYPE or entities (refused unread)")

    def start(self, tag: str, attributes: dict) -> None:
        self.elements += 1
        if self.elements > MAX_CLF_ELEMENTS:
            raise ValueError(f"{self.path}: more than {MAX_CLF_ELEMENTS} XML elements; a creative CLF holds a few dozen")
        if _local(tag) == "Array":
            size = _dim(attributes.get("dim", ""), self.path)
            self.array_budget = 3 * size**3 * BYTES_PER_NUMBER + 1024
        self.tree.start(tag, attributes)

    def end(self, tag: str) -> None:
        if _local(tag) == "Array":
            self.array_budget = None
        self.tree.end(tag)

    def data(self, text: str) -> None:
        if self.array_budget is not None:
            self.array_budget -= len(text)
            if self.array_budget < 0:
                raise ValueError(f"{self.path}: the LUT3D Array holds far more text than its dim declares numbers")
        else:
            self.text += len(text)
            if self.text > MAX_TEXT_BYTES:
                raise ValueError(f"{self.path}: more than {MAX_TEXT_BYTES} bytes of text outside the LUT3D Array")
        self.tree.data(text)


def _local(tag: str) -> str:
    """A name without its XML namespace (``{urn:...}name``) or prefix (``clf:name``)."""
    return tag.rsplit("}", 1)[-1].rsplit(":", 1)[-1]


def _tag(node: ElementTree.Element) -> str:
    """The element's name without its XML namespace (CLF 3 files may declare ``urn:AMPAS:CLF:v3.0``)."""
    return _local(node.tag)


def _depth_scale(node: ElementTree.Element, attribute: str, path) -> float:
    depth = node.get(attribute, "32f")
    if depth not in _DEPTH_SCALES:
        raise ValueError(f"{path}: {_tag(node)} {attribute} must be one of {tuple(_DEPTH_SCALES)}, got {depth[:80]!r}")
    return _DEPTH_SCALES[depth]


def _range_values(node: ElementTree.Element, path) -> dict:
    """A ``Range`` node's four bounds, normalised by its bit depths; every bound is required."""
    scales = {"In": _depth_scale(node, "inBitDepth", path), "Out": _depth_scale(node, "outBitDepth", path)}
    values = {}
    for side in ("In", "Out"):
        for end in ("min", "max"):
            name = f"{end}{side}Value"
            child = next((c for c in node if _tag(c) == name), None)
            if child is None:
                raise ValueError(f"{path}: a Range needs {name} (a Range open at one end does not clamp like a LUT)")
            values[name] = _number(child.text, name, path) / scales[side]
    return values


def _domain(node: ElementTree.Element, path) -> tuple:
    """The lattice domain of a ``Range`` before the table (with or without ``noClamp``: the ``LUT3D`` clamps its input
    to the lattice either way)."""
    _style(node, path)
    values = _range_values(node, path)
    if (values["minOutValue"], values["maxOutValue"]) != (0.0, 1.0) or not values["minInValue"] < values["maxInValue"]:
        raise ValueError(f"{path}: the Range before the LUT3D must map [a, b] (a < b) onto [0, 1], got {values}")
    return values["minInValue"], values["maxInValue"]


def _clamp(node: ElementTree.Element, path):
    """The output clamp of a ``Range`` after the table: its bounds, or ``None`` for ``style="noClamp"`` (which only
    scales, here by 1: the same bounds in and out)."""
    values = _range_values(node, path)
    low, high = values["minInValue"], values["maxInValue"]
    if (values["minOutValue"], values["maxOutValue"]) != (low, high) or not low < high:
        raise ValueError(f"{path}: the Range after the LUT3D must keep its bounds (the same in and out), got {values}")
    return None if _style(node, path) == "noClamp" else (low, high)


def _style(node: ElementTree.Element, path) -> str:
    """A ``Range``'s style: ``"Clamp"`` (the default) or ``"noClamp"``."""
    style = node.get("style", "Clamp")
    if style not in ("Clamp", "noClamp"):
        raise ValueError(f"{path}: a Range's style must be Clamp or noClamp, got {style[:80]!r}")
    return style


def _table(node: ElementTree.Element, path) -> tuple:
    """The ``LUT3D``'s entries as a ``(S, S, S, 3)`` table indexed ``[b, g, r]``, and its interpolation."""
    interpolation = node.get("interpolation", "trilinear")
    if interpolation not in ("trilinear", "tetrahedral"):
        raise ValueError(f"{path}: LUT3D interpolation must be trilinear or tetrahedral, got {interpolation[:80]!r}")
    _depth_scale(node, "inBitDepth", path)  # the lattice spans its input's [0, 1] at any known depth; another is refused
    array = next((child for child in node if _tag(child) == "Array"), None)
    if array is None:
        raise ValueError(f"{path}: the LUT3D has no Array")
    size = _dim(array.get("dim", ""), path)
    try:
        values = np.array((array.text or "").split(), dtype=np.float64)
    except ValueError as error:
        raise ValueError(f"{path}: the LUT3D Array holds a value that is not a number ({error})") from None
    if values.size != 3 * size**3:
        raise ValueError(f"{path}: the LUT3D Array of dim {size} {size} {size} 3 needs {3 * size**3} numbers, got {values.size}")
    values = values / _depth_scale(node, "outBitDepth", path)
    with np.errstate(over="ignore"):  # a value beyond float32 becomes inf here, and is refused as such
        held = values.astype(np.float32)
    if not np.isfinite(held).all():
        raise ValueError(f"{path}: the LUT3D Array holds a value that is not finite in float32")
    table = torch.from_numpy(held).reshape(size, size, size, 3)  # [r, g, b]: blue fastest
    return table.permute(2, 1, 0, 3).contiguous(), interpolation


def _dim(text: str, path) -> int:
    words = text.split()
    if len(words) != 4 or not all(word.isdigit() for word in words) or words[3] != "3" or len(set(words[:3])) != 1:
        raise ValueError(f"{path}: a LUT3D Array's dim must be 'S S S 3', got {text[:80]!r}")
    size = int(words[0])
    if not MIN_SIZE <= size <= MAX_SIZE:
        raise ValueError(f"{path}: the LUT3D size must lie in [{MIN_SIZE}, {MAX_SIZE}], got {size}")
    return size


def _number(text, name: str, path) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise ValueError(f"{path}: {name} must be a number, got {str(text)[:80]!r}") from None
    if not np.isfinite(value):
        raise ValueError(f"{path}: {name} must be finite, got {str(text)[:80]!r}")
    return value
