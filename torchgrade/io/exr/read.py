"""``read_exr``: one layer of one view of one part of an OpenEXR file, as a float32 tensor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ...base.params import check_choice
from ...base.files import check_regular
from ...color import REC709_CHROMATICITIES
from .chromaticities import ADAPTATIONS, to_rec709_matrix
from .decode import (
    MAX_BYTES,
    MAX_PIXELS,
    check_budget,
    decode,
    decode_strips,
    selective,
)
from .header_bytes import check_headers
from .layout import ExrPart, exr_info
from .yca import luminance_weights, yca_to_rgb

__all__ = ["read_exr"]

WINDOWS = ("data", "display")
_STRIP_LINES = 256
"""Rows converted at a time by the colour matrix: bounds its temporary to a strip of the image."""
_COLOUR = ("R", "G", "B", "A", "Y", "RY", "BY")
"""The channels a colour layer is read from; its others (``Z``) are neither returned nor decoded."""


def _wanted(part: ExrPart, view, layer: str) -> dict[str, str]:
    """``{channel: full name}`` of ``layer`` in ``view`` (None: the part's default view), else in no view."""
    view = view if view is not None else (part.views[0] if part.views else None)
    for owner in (view, None):
        found = {letter: name for name, (v, lay, letter) in part.names.items() if (v, lay) == (owner, layer)}
        if found:
            return found
    return {}


def _choose(path, parts: list[ExrPart], part, view, layer) -> tuple[ExrPart, dict[str, str]]:
    """The part to read and its channels: ``part`` by index or name, else the first that has the layer."""
    if part is not None:
        matches = [p for p in parts if part in (p.index, p.name)]
        if not matches:
            raise ValueError(f"{path}: no part {part!r} (parts: {[(p.index, p.name) for p in parts]})")
        candidates = matches
    else:
        candidates = [p for p in parts if view is None or view in p.views]
    for candidate in candidates:
        channels = _wanted(candidate, view, layer or "")
        if channels and (layer is not None or channels.keys() & {"R", "G", "B", "Y"}):
            return candidate, channels
    held = {p.index: sorted(f"{v}:{lay or '(main)'}" if v else lay or "(main)" for v, lay in p.layers) for p in parts}
    what = f"layer {layer!r}" if layer is not None else "R, G, B or Y channels in the main layer"
    raise ValueError(f"{path}: no {what}{'' if view is None else f' of view {view!r}'} "
                     f"(layers by part, as view:layer: {held}; choose with layer=, view=, part=)")


def _check_sampling(path, part: ExrPart, channels: dict[str, str]) -> None:
    """Every channel full size, but RY and BY at 2×2 subsampling."""
    for letter, name in channels.items():
        sampling = (2, 2) if letter in ("RY", "BY") and {"Y"} <= channels.keys() else (1, 1)
        if part.channels[name] != sampling:
            raise ValueError(f"{path}: channel {name} has sampling {part.channels[name]}; read_exr reads {sampling}")


def _check_shapes(path, part: ExrPart, channels: dict[str, str], pixels: dict) -> None:
    """Every channel decoded at the size its sampling gives."""
    height, width = part.size()
    for name in channels.values():
        xs, ys = part.channels[name]
        expected = (-(-height // ys), -(-width // xs))
        if getattr(pixels[name], "shape", None) != expected:
            raise ValueError(f"{path}: channel {name} decoded as {getattr(pixels[name], 'shape', None)}, not {expected}")


def _canvas(part: ExrPart, window: str, count: int) -> tuple[torch.Tensor, torch.Tensor, tuple[slice, slice]]:
    """The float32 output over the window (0 outside the data window), the view of it the data window's
    pixels land in, and which rows and columns of the data window land there."""
    height, width = part.size(window)
    image = torch.zeros(count, height, width) if window == "display" else torch.empty(count, height, width)
    dx0, dy0, dx1, dy1 = part.data_window
    wx0, wy0 = (dx0, dy0) if window == "data" else part.display_window[:2]
    x0, y0 = max(dx0, wx0), max(dy0, wy0)
    x1, y1 = max(min(dx1, wx0 + width - 1), x0 - 1), max(min(dy1, wy0 + height - 1), y0 - 1)
    target = image[:, y0 - wy0:y1 - wy0 + 1, x0 - wx0:x1 - wx0 + 1]
    return image, target, (slice(y0 - dy0, y1 - dy0 + 1), slice(x0 - dx0, x1 - dx0 + 1))


def _luminance_chroma(part: ExrPart, channels: dict[str, str], pixels: dict, target: torch.Tensor, crop) -> None:
    """RGB from Y, RY, BY into ``target``: directly when the whole data window lands there, else through a copy."""
    weights = luminance_weights(part.chromaticities or REC709_CHROMATICITIES)
    chroma = [pixels.pop(channels[c]) if c in channels else None for c in ("RY", "BY")]
    shape = next(c.shape for c in chroma if c is not None)
    chroma = [c if c is not None else np.zeros(shape, np.float16) for c in chroma]
    y = pixels.pop(channels["Y"])
    if target.shape[1:] == y.shape:
        yca_to_rgb(y, chroma.pop(0), chroma.pop(0), weights, out=target)
    else:
        target.copy_(yca_to_rgb(y, chroma.pop(0), chroma.pop(0), weights)[:, crop[0], crop[1]])


def _order(channels: dict[str, str]) -> tuple[bool, list[str], int]:
    """Whether the layer is luminance/chroma (RGB rebuilt into the first three channels), and the
    letters the tensor's channels from ``first`` on hold: RGB(A) as OpenEXR's RGBA interface gives
    it (a letter the layer lacks is zeros), or every channel."""
    letters = set(channels)
    if "Y" in letters and letters & {"RY", "BY"} and not letters & {"R", "G", "B"}:
        return True, ["A"] if "A" in letters else [], 3
    if letters & {"R", "G", "B", "Y"}:
        grey = "Y" if not letters & {"R", "G", "B"} else None
        return False, [grey or c for c in "RGB"] + (["A"] if "A" in letters else []), 0
    return False, sorted(letters), 0


def _fill(path, part: ExrPart, channels: dict[str, str], pixels: dict, target: torch.Tensor, crop) -> None:
    """Copy the decoded layer into ``target`` in ``_order``.

    Each decoded plane is dropped once copied, so the decoded samples and the output overlap little.
    """
    _check_shapes(path, part, channels, pixels)
    luminance_chroma, names, first = _order(channels)
    if luminance_chroma:
        _luminance_chroma(part, channels, pixels, target[:3], crop)
    for index, letter in enumerate(names, start=first):
        if letter not in channels:
            target[index].zero_()
            continue
        target[index].numpy()[...] = pixels[channels[letter]][crop[0], crop[1]]  # the arrays may be read-only
        if letter not in names[index - first + 1:]:
            del pixels[channels[letter]]


def _convert(image: torch.Tensor, matrix: torch.Tensor) -> None:
    matrix = matrix.float()
    for top in range(0, image.shape[1], _STRIP_LINES):
        strip = image[:3, top:top + _STRIP_LINES]
        strip.copy_(torch.einsum("ij,jhw->ihw", matrix, strip))


def read_exr(path, to_rec709: bool = False, *, adaptation: str = "auto", layer: str | None = None,
             view: str | None = None, part: int | str | None = None, window: str = "data",
             max_pixels: int = MAX_PIXELS, max_bytes: int = MAX_BYTES) -> torch.Tensor:
    """Read one layer of an OpenEXR file as a float32 tensor ``(C, H, W)``.

    By default this is what OpenEXR's RGBA interface gives: the main layer (channels ``R``, ``G``,
    ``B``, ``A``, or luminance/chroma ``Y``, ``RY``, ``BY``) of the default view (the first of a
    ``multiView`` attribute) of the first part that has one, as ``(3, H, W)`` RGB or ``(4, H, W)``
    RGBA (every stage grades the colour and returns the alpha unchanged); missing R, G or B are zeros,
    luminance/chroma is reconstructed to RGB as OpenEXR does (see :mod:`torchgrade.io.exr.yca`), a Y-only
    file is grey. Other channels (``mask.R``, ``left.R``) never mix in. :func:`exr_info` lists what a file
    holds.

    Args:
        to_rec709: convert RGB from the file's ``chromaticities`` to linear Rec.709 (files without
            the attribute are Rec.709 already); ``adaptation`` says how the white is moved to D65:
            ``"bradford"`` (ACES convention), ``"none"``, or ``"auto"``: none for CIE XYZ primaries,
            Bradford for any other (see ``ADAPTATIONS``).
        layer: a layer name (``"diffuse"``); a colour layer reads as above, any other as all its
            channels in name order. view: a view of a multi-view file or part (``"left"``).
        part: a part index or name; by default the first part holding the layer in the view.
        window: ``"data"`` (the pixels stored) or ``"display"`` (the frame: outside the data window
            is 0, so frames of a sequence share one size).
        max_pixels: the budget of pixels checked from the headers before decoding (ValueError).
        max_bytes: the budget of bytes checked from the headers before decoding (ValueError).

    Raises ``ValueError`` for damaged, deep, over-budget files and for a missing layer, view or part:
    the header bytes decide before any pixel is decoded (a header lacking an attribute the format
    requires, a chunk offset table the bindings could not follow soundly, the bytes a read would take
    past ``max_bytes``, each named with its field and size; see :mod:`torchgrade.io.exr.chunks` and
    :func:`torchgrade.io.exr.decode.check_budget`).

    Examples:
        >>> import pathlib, tempfile, torch
        >>> from torchgrade.io import write_exr
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgba.exr"
        >>> write_exr(path, torch.ones(4, 2, 3))
        >>> read_exr(path).shape, read_exr(path, window="display").shape
        (torch.Size([4, 2, 3]), torch.Size([4, 2, 3]))
    """
    path = Path(path)
    check_regular(path, "EXR file")
    check_choice("window", window, WINDOWS)
    check_choice("adaptation", adaptation, ADAPTATIONS)
    check_headers(path)  # first: the bindings stand in defaults for some missing attributes, refuse others unnamed
    parts = exr_info(path)
    chosen, channels = _choose(path, parts, part, view, layer)
    colour = channels.keys() & {"R", "G", "B", "Y"}
    if colour:
        channels = {letter: name for letter, name in channels.items() if letter in _COLOUR}
    count = (3 + ("A" in channels)) if colour else len(channels)
    check_budget(path, parts, chosen, list(channels.values()), window, count, max_pixels, max_bytes)
    matrix = to_rec709_matrix(chosen.chromaticities, adaptation) if to_rec709 and colour and chosen.chromaticities else None
    _check_sampling(path, chosen, channels)
    image, target, crop = _canvas(chosen, window, count)
    luminance_chroma, letters, _ = _order(channels)
    if selective(parts, chosen, list(channels.values())) and not luminance_chroma:
        decode_strips(path, chosen, [channels.get(letter) for letter in letters], target, crop)
    else:
        _fill(path, chosen, channels, decode(path, parts, chosen, list(channels.values())), target, crop)
    if matrix is not None:
        _convert(image, matrix)
    return image
