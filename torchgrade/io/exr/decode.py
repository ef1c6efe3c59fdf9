"""Decoding an untrusted OpenEXR file: budget checked from the headers first, library errors fatal.

The bindings' ``OpenEXR.File`` decodes every channel of every part at once. Only their deprecated
``OpenEXR.InputFile`` decodes chosen channels, and only of the first part at full resolution (its
``channels`` sizes subsampled channels wrongly). So a part other than a single-part file's one is
first copied out, still compressed, into a single-part file in a temporary folder
(:mod:`torchgrade.io.exr.single_part`; ``InputFile`` reads the first part in place). Full-resolution
channels that leave other channels or parts out are then decoded through ``InputFile``, a strip of
rows at a time straight into the tensor (``decode_strips``); everything else through ``File``, every
channel of that one part (``decode``; see ``selective``). The budget counts what the chosen path
decodes (for a strip read the whole layer, though it holds a strip at a time).

Damage is found without watching what the library prints: the process's standard output and error
are shared with every other thread, so nothing of what they carry can be told to come from a read.
Instead the library is only given a part of a file whose headers and chunk offset table were checked
from its bytes first (:mod:`torchgrade.io.exr.chunks`), and what it still cannot decode (a chunk
whose data does not decompress) it reports in ways of its own: ``InputFile`` raises, and ``File``
leaves the part out of what it returns. Either rejects the file with a ``ValueError``; the library
prints its own complaint then (OpenEXR's core to standard error, the bindings a warning to
``sys.stdout``), never for a file that reads. Reads in several threads decode at once. A read
decodes one part only: damage in another part's chunks goes unseen.
"""

from __future__ import annotations

import contextlib
import tempfile
from pathlib import Path

import numpy as np

from .chunks import chunk_table
from .layout import ExrPart
from .single_part import write_single_part

from ...base.budget import MAX_PIXELS as BUDGET_PIXELS

__all__ = ["MAX_BYTES", "MAX_PIXELS", "STRIP_BYTES", "check_budget", "decode", "decode_strips", "selective"]

MAX_PIXELS = BUDGET_PIXELS
"""Largest window read_exr accepts by default: the library's one pixel budget (:data:`torchgrade.base.budget.MAX_PIXELS`,
8192x8192), which every decoded image passes."""

MAX_BYTES = 1 << 31
"""Default bound (2 GiB) on the memory a read may take: every sample the bindings decode (2 bytes
half, 4 float), the row of tiles they buffer for a tiled part, and the float32 tensor returned."""

STRIP_BYTES = 1 << 18
"""Decoded samples a selective read holds at a time (256 KiB): it decodes that many rows per strip."""

_DTYPES = {0: np.uint32, 1: np.float16, 2: np.float32}
"""numpy type of OpenEXR's UINT, HALF and FLOAT pixel types."""


def selective(parts: list[ExrPart], chosen: ExrPart, names) -> bool:
    """Whether ``decode_strips`` reads the channels ``names`` of ``chosen``: full resolution, and fewer
    than the file holds (``decode`` reads every channel of the part).

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> from torchgrade.io import exr_info
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 4))
        >>> parts = exr_info(path)
        >>> selective(parts, parts[0], ["R", "G", "B"]), selective(parts, parts[0], ["R"])
        (False, True)
    """
    full = all(chosen.channels[name] == (1, 1) for name in names)
    return full and (len(parts) > 1 or set(names) != set(chosen.channels))


def check_budget(path, parts: list[ExrPart], chosen: ExrPart, names, window: str, output_channels: int, max_pixels: int,
                 max_bytes: int) -> None:
    """Raise ``ValueError`` naming the file, the header field and its size when decoding channels ``names``
    of ``chosen`` (as ``decode_strips`` or ``decode`` do) and returning ``output_channels`` over ``window``
    would pass either bound.

    The bytes are every sample decoded, the float32 tensor returned (over the display window when
    that is the one returned) and, for a tiled part, the row of tiles OpenEXR's scanline interface
    (through which both ways decode) buffers for each channel: a tile's height times the data
    window's width, however few rows the data window has (``InputFile::Data::setFrameBuffer`` in
    ImfInputFile.cpp). The field named is the one behind the largest of the three.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> from torchgrade.io import exr_info
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 64, 64))
        >>> parts = exr_info(path)
        >>> check_budget(path, parts, parts[0], ["R", "G", "B"], "data", 3, max_pixels=1 << 20, max_bytes=1000)
        Traceback (most recent call last):
        ValueError: ...rgb.exr: part 0 dataWindow 64x64 makes reading need about 73728 bytes (24576 decoded + 49152 returned), above the budget of 1000 bytes (max_bytes)
    """
    for part in parts:
        if part.deep:
            raise ValueError(f"{path}: part {part.index} holds deep data ({part.kind}), which read_exr does not read; "
                             "flatten it first (e.g. with OpenImageIO's oiiotool --flatten)")
        height, width = part.size()
        if height <= 0 or width <= 0 or height * width > max_pixels:
            raise ValueError(f"{path}: part {part.index} dataWindow {width}x{height} is empty or above the "
                             f"budget of {max_pixels} pixels (max_pixels)")
    decoded_names = names if selective(parts, chosen, names) else chosen.channels
    height, width = chosen.size(window)
    shown = "displayWindow" if window == "display" else "dataWindow"
    if height <= 0 or width <= 0 or height * width > max_pixels:
        raise ValueError(f"{path}: {shown} {width}x{height} is empty or above the budget of {max_pixels} pixels (max_pixels)")
    data_height, data_width = chosen.size()
    decoded, returned = _decoded_bytes(chosen, decoded_names), 4 * output_channels * height * width
    needs = [(decoded, f"dataWindow {data_width}x{data_height}"), (returned, f"{shown} {width}x{height}")]
    buffered = ""
    if chosen.tile_size is not None:
        tile_width, tile_height = chosen.tile_size
        rows = tile_height * data_width * sum(chosen.sample_bytes[name] for name in decoded_names)
        needs.append((rows, f"tiles (tileDesc) {tile_width}x{tile_height}"))
        buffered = f" + {rows} in the library's row of tiles"
    total = sum(size for size, _ in needs)
    if total > max_bytes:
        field = max(needs, key=lambda need: need[0])[1]
        raise ValueError(f"{path}: part {chosen.index} {field} makes reading need about {total} bytes "
                         f"({decoded} decoded + {returned} returned{buffered}), above the budget of {max_bytes} bytes (max_bytes)")


def _decoded_bytes(part: ExrPart, names) -> int:
    height, width = part.size()
    samplings = {name: part.channels[name] for name in names}
    return sum(part.sample_bytes[name] * -(-height // ys) * -(-width // xs) for name, (xs, ys) in samplings.items())


@contextlib.contextmanager
def _decoding(path, source):
    """Turn what the library raises meanwhile, decoding ``source`` (``path`` or a copy of one of its
    parts), into ``ValueError`` naming ``path``."""
    try:
        yield
    except MemoryError:
        raise ValueError(f"{path}: not enough memory to decode the pixels (use a smaller max_bytes)") from None
    except Exception as error:
        message = str(error).replace(f"{source}: ", "").replace(str(source), str(path))
        raise ValueError(f"{path}: cannot decode OpenEXR pixels ({message})") from None


@contextlib.contextmanager
def _part_file(path, chosen: ExrPart, alone: bool):
    """The file to decode part ``chosen`` of ``path`` from, once the part's chunk offset table is checked
    (``ValueError`` otherwise): ``path`` itself when ``alone`` (the part is the file's only one, or the
    first, which ``InputFile`` reaches), else a single-part copy of the part in a temporary folder,
    removed afterwards. A part whose compression the checks do not know is left to the library when alone,
    and refused otherwise (the copy needs its table)."""
    table = chunk_table(path, chosen)
    if alone:
        yield Path(path)
        return
    if table is None:
        raise ValueError(f"{path}: part {chosen.index} is compressed with a code whose chunk layout torchgrade does not "
                         "know, so it cannot be copied out of its multi-part file to decode")
    with tempfile.TemporaryDirectory(prefix="torchgrade-exr-") as folder:
        copy = Path(folder) / "part.exr"
        with open(copy, "wb") as target:
            write_single_part(path, chosen, table, target)
        yield copy


def decode(path, parts: list[ExrPart], chosen: ExrPart, names: list[str]) -> dict:
    """Channels ``names`` of part ``chosen`` as ``{name: numpy array}``, decoding every channel of
    that part (of a single-part copy of it in a multi-part file), or ``ValueError``.

    What the library raises, the part missing from what it decoded (it leaves out a part it could
    not decode) or any channel missing reject the file; a ``MemoryError`` becomes a ``ValueError`` too.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> from torchgrade.io import exr_info
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.zeros(3, 2, 4))
        >>> parts = exr_info(path)
        >>> {name: array.shape for name, array in decode(path, parts, parts[0], ["R", "G"]).items()}
        {'R': (2, 4), 'G': (2, 4)}
    """
    import OpenEXR

    with _part_file(path, chosen, alone=len(parts) == 1) as source, _decoding(path, source):
        opened = OpenEXR.File(str(source), separate_channels=True)
        decoded = [{name: channel.pixels for name, channel in part.channels.items()} for part in opened.parts]
    if len(decoded) != 1:  # the bindings leave out a part they could not decode, printing why to sys.stdout
        raise ValueError(f"{path}: damaged OpenEXR file (the library could not decode the pixels of part {chosen.index})")
    if set(decoded[0]) != set(chosen.channels):
        raise ValueError(f"{path}: damaged OpenEXR file (the library returned other channels than the header lists)")
    return {name: decoded[0][name] for name in names}


def decode_strips(path, chosen: ExrPart, sources: list, target, crop: tuple[slice, slice]) -> None:
    """Decode channel ``sources[i]`` of part ``chosen`` (``None``: zeros) into ``target[i]``, ``STRIP_BYTES``
    of samples at a time, or raise ``ValueError`` as ``decode`` does.

    Every row of the data window is decoded (so damage anywhere in the layer rejects the file); rows
    ``crop[0]`` and columns ``crop[1]`` of it land in the tensor ``target``.

    Examples:
        >>> import pathlib, tempfile, torch, torchgrade as tg
        >>> from torchgrade.io import exr_info
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "rgb.exr"
        >>> tg.io.write_exr(path, torch.arange(24.0).reshape(3, 2, 4))
        >>> target = torch.empty(2, 2, 4)
        >>> decode_strips(path, exr_info(path)[0], ["B", None], target, (slice(0, 2), slice(0, 4)))
        >>> target[:, 1]
        tensor([[20., 21., 22., 23.],
                [ 0.,  0.,  0.,  0.]])
    """
    import OpenEXR

    names = sorted({name for name in sources if name is not None})
    height, width = chosen.size()
    rows = max(1, STRIP_BYTES // (width * sum(chosen.sample_bytes[name] for name in names)))
    out, top = target.numpy(), chosen.data_window[1]
    for index, name in enumerate(sources):
        if name is None:
            out[index] = 0
    with _part_file(path, chosen, alone=chosen.index == 0) as source, _decoding(path, source):
        opened = OpenEXR.InputFile(str(source))
        try:
            types = opened.header()["channels"]
            by_type: dict[int, list[str]] = {}
            for name in names:
                by_type.setdefault(types[name].type.v, []).append(name)
            for first in range(0, height, rows):
                last = min(first + rows, height)
                strip = {}
                for kind, group in by_type.items():  # scanlines: data-window y, both ends included
                    samples = opened.channels(group, types[group[0]].type, top + first, top + last - 1)
                    strip.update({n: np.frombuffer(s, _DTYPES[kind]).reshape(last - first, width) for n, s in zip(group, samples)})
                low, high = max(crop[0].start, first), min(crop[0].stop, last)
                for index, name in enumerate(sources):
                    if name is not None and low < high:
                        out[index, low - crop[0].start:high - crop[0].start] = strip[name][low - first:high - first, crop[1]]
        finally:
            opened.close()
