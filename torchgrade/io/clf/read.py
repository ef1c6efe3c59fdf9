"""Reading a creative CLF LUT: a ``LUT3D`` node, optionally after a ``Range`` onto [0, 1] (the lattice domain) and
before a ``Range`` that clamps (the output range), checked strictly before a table is built.

A CLF file is untrusted XML: its size is bounded before parsing (:data:`MAX_CLF_BYTES`), expat refuses entity
expansion bombs, and every number is checked finite and counted against the ``Array``'s ``dim``.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ElementTree

import numpy as np
import torch

from ...lut import LUT3D, MAX_SIZE, MIN_SIZE

__all__ = ["MAX_CLF_BYTES", "read_clf"]

MAX_CLF_BYTES = 256 * 2**20
"""Largest CLF file read (256 MiB: a 129³ table at 40 bytes a number); a larger one is refused before parsing."""

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
        raise ValueError(f"{path}: a creative CLF holds one LUT3D and optional Range nodes, got {kinds or 'no nodes'}; "
                         "apply other CLF files with OpenColorIO")
    at = kinds.index("LUT3D")
    if at > 1 or len(kinds) - at > 2:
        raise ValueError(f"{path}: at most one Range before the LUT3D and one after it, got {kinds}")
    domain = _domain(nodes[0], path) if at == 1 else (0.0, 1.0)
    output_range = _clamp(nodes[at + 1], path) if at + 1 < len(nodes) else None
    table, interpolation = _table(nodes[at], path)
    return LUT3D(table, "linear", domain, output_range=output_range, interpolation=interpolation)


def _parse(path) -> ElementTree.Element:
    size = os.path.getsize(path)
    if size > MAX_CLF_BYTES:
        raise ValueError(f"{path}: {size} bytes is more than a CLF LUT may hold ({MAX_CLF_BYTES} bytes)")
    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError as error:
        raise ValueError(f"{path}: not a well-formed CLF file: {error}") from None
    if _tag(root) != "ProcessList":
        raise ValueError(f"{path}: a CLF file's root is ProcessList, got {_tag(root)}")
    return root


def _tag(node: ElementTree.Element) -> str:
    """The element's name without its XML namespace (CLF 3 files may declare ``urn:AMPAS:CLF:v3.0``)."""
    return node.tag.rsplit("}", 1)[-1]


def _depth_scale(node: ElementTree.Element, attribute: str, path) -> float:
    depth = node.get(attribute, "32f")
    if depth not in _DEPTH_SCALES:
        raise ValueError(f"{path}: {_tag(node)} {attribute} must be one of {tuple(_DEPTH_SCALES)}, got {depth!r}")
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
    values = _range_values(node, path)
    if (values["minOutValue"], values["maxOutValue"]) != (0.0, 1.0) or not values["minInValue"] < values["maxInValue"]:
        raise ValueError(f"{path}: the Range before the LUT3D must map [a, b] (a < b) onto [0, 1], got {values}")
    return values["minInValue"], values["maxInValue"]


def _clamp(node: ElementTree.Element, path) -> tuple:
    values = _range_values(node, path)
    low, high = values["minInValue"], values["maxInValue"]
    if (values["minOutValue"], values["maxOutValue"]) != (low, high) or not low < high:
        raise ValueError(f"{path}: the Range after the LUT3D must clamp (the same bounds in and out), got {values}")
    return low, high


def _table(node: ElementTree.Element, path) -> tuple:
    """The ``LUT3D``'s entries as a ``(S, S, S, 3)`` table indexed ``[b, g, r]``, and its interpolation."""
    interpolation = node.get("interpolation", "trilinear")
    if interpolation not in ("trilinear", "tetrahedral"):
        raise ValueError(f"{path}: LUT3D interpolation must be trilinear or tetrahedral, got {interpolation!r}")
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
        raise ValueError(f"{path}: a LUT3D Array's dim must be 'S S S 3', got {text!r}")
    size = int(words[0])
    if not MIN_SIZE <= size <= MAX_SIZE:
        raise ValueError(f"{path}: the LUT3D size must lie in [{MIN_SIZE}, {MAX_SIZE}], got {size}")
    return size


def _number(text, name: str, path) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise ValueError(f"{path}: {name} must be a number, got {text!r}") from None
    if not np.isfinite(value):
        raise ValueError(f"{path}: {name} must be finite, got {text!r}")
    return value
