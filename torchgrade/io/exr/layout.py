"""What an OpenEXR file holds, from its headers alone: parts, views, layers, windows, chromaticities.

Channel names follow OpenEXR's multi-view convention (ImfMultiView): in a file with a ``multiView``
attribute the first view listed is the default one; a name without periods belongs to the default
view; otherwise the next-to-last period-separated component names the view when it is one of the
listed views (``left.R``, ``forward.left.u``), and the channel belongs to no view when it is not
(``disparityL.x``). What remains once the view component is removed is ``layer.channel``; the main
layer is the empty name (``R``, ``G``, ``B``, ``A``, ``Y``, ``RY``, ``BY``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ...base.files import check_regular
from .header_bytes import PartBytes, part_bytes

__all__ = ["ExrPart", "exr_info", "split_channel_name"]


@dataclass(frozen=True)
class ExrPart:
    """One part of an OpenEXR file as its header describes it.

    ``layers`` maps ``(view, layer)`` to the channel names (without layer and view) in that layer;
    ``view`` is ``None`` for channels that belong to no view. ``channels`` maps each full channel
    name to its ``(x_sampling, y_sampling)``. Windows are ``(x_min, y_min, x_max, y_max)``, inclusive.
    ``chromaticities`` is ``((xr, yr), (xg, yg), (xb, yb), (xw, yw))`` or ``None`` (Rec.709 by the
    OpenEXR convention).

    Examples:
        >>> import tempfile, pathlib, torch
        >>> from torchgrade.io import exr_info, write_exr
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     path = pathlib.Path(folder) / "frame.exr"
        ...     write_exr(path, torch.zeros(3, 2, 4))
        ...     part = exr_info(path)[0]
        >>> part.data_window
        (0, 0, 3, 1)
    """

    index: int
    name: str | None
    kind: str
    data_window: tuple[int, int, int, int]
    display_window: tuple[int, int, int, int]
    views: tuple[str, ...]
    chromaticities: tuple | None
    channels: dict = field(repr=False)
    layers: dict = field(repr=False)
    names: dict = field(repr=False)
    """``{full channel name: (view, layer, channel)}``."""
    sample_bytes: dict = field(repr=False)
    """``{full channel name: 2 (half) or 4 (float, uint)}``; 4 where the header bytes did not say."""
    tile_size: tuple[int, int] | None = field(default=None, repr=False)
    """``(width, height)`` of a tiled part's tiles, from the header bytes; ``None`` for scanlines, or
    where the header bytes did not say (such a file fails :func:`torchgrade.io.exr.chunks.chunk_table`
    before anything is decoded)."""

    @property
    def deep(self) -> bool:
        """Whether the part holds deep (many samples per pixel) data."""
        return self.kind.startswith("deep")

    def size(self, window: str = "data") -> tuple[int, int]:
        """``(height, width)`` of the data or display window."""
        x_min, y_min, x_max, y_max = self.data_window if window == "data" else self.display_window
        return y_max - y_min + 1, x_max - x_min + 1


def split_channel_name(name: str, views: tuple[str, ...]) -> tuple[str | None, str, str]:
    """``(view, layer, channel)`` of a full channel name under OpenEXR's multi-view rules.

    Examples:
        >>> split_channel_name("forward.left.u", ("right", "left"))
        ('left', 'forward', 'u')
        >>> split_channel_name("R", ("right", "left")), split_channel_name("mask.R", ())
        (('right', '', 'R'), (None, 'mask', 'R'))
    """
    pieces = name.split(".")
    default = views[0] if views else None
    if len(pieces) == 1:
        return default, "", name
    if views and pieces[-2] in views:
        return pieces[-2], ".".join(pieces[:-2]), pieces[-1]
    return None, ".".join(pieces[:-1]), pieces[-1]


def _window(box) -> tuple[int, int, int, int]:
    (x_min, y_min), (x_max, y_max) = box
    return int(x_min), int(y_min), int(x_max), int(y_max)


def _chromaticities(header: dict):
    values = header.get("chromaticities")
    if values is None:
        return None
    return tuple((float(values[i]), float(values[i + 1])) for i in range(0, 8, 2))


def _describe(index: int, part, raw: PartBytes | None) -> ExrPart:
    header = part.header
    views = tuple(header.get("multiView") or ())
    part_view = header.get("view")  # in a multi-part file, every channel of the part is in its view
    if not views and part_view:
        views = (str(part_view),)
    channels: dict[str, tuple[int, int]] = {}
    layers: dict[tuple[str | None, str], list[str]] = {}
    names: dict[str, tuple[str | None, str, str]] = {}
    for channel in header.get("channels") or ():
        channels[channel.name] = (int(channel.xSampling), int(channel.ySampling))
        view, layer, letter = split_channel_name(channel.name, views)
        if part_view and not header.get("multiView"):
            view, layer = str(part_view), channel.name.rpartition(".")[0]
        names[channel.name] = (view, layer, letter)
        layers.setdefault((view, layer), []).append(letter)
    kind = str(header.get("type", "scanlineimage")).split(".")[-1]  # the bindings' default, as its enum prints
    sizes = raw.sample_bytes if raw is not None and raw.sample_bytes.keys() == channels.keys() else dict.fromkeys(channels, 4)
    return ExrPart(index, header.get("name"), kind, _window(header["dataWindow"]), _window(header["displayWindow"]),
                   views, _chromaticities(header), channels, {key: sorted(value) for key, value in layers.items()}, names,
                   sizes, raw.tile_size if raw is not None and kind in ("tiledimage", "deeptile") else None)


def exr_info(path) -> list[ExrPart]:
    """Every part of the file at ``path``, read from the headers only (no pixel is decoded).

    Raises ``ValueError`` when the file is not a readable OpenEXR file. This is what the bindings read
    in the headers: a header that lacks an attribute the format requires is described with the
    default they stand in (reading it refuses it: see :mod:`torchgrade.io.exr.chunks`).

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 4))
        >>> part, = exr_info(path)
        >>> part.kind, part.size(), part.layers
        ('scanlineimage', (2, 4), {(None, ''): ['B', 'G', 'R']})
    """
    import OpenEXR  # the bindings load at the first read, not with torchgrade.io

    check_regular(path, "EXR file")
    try:
        raw = part_bytes(path) or []  # first: it refuses headers past their budgets before OpenEXR's parser runs
        opened = OpenEXR.File(str(path), header_only=True)
        return [_describe(index, part, raw[index] if index < len(raw) else None) for index, part in enumerate(opened.parts)]
    except Exception as error:  # the bindings raise RuntimeError/OSError/ValueError/UnicodeError for damaged headers
        raise ValueError(f"{path}: not a readable OpenEXR file ({error})") from None
