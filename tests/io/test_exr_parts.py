"""A part of a multi-part OpenEXR file read on its own: bit-identical to the library's whole-file
decode, for every part and layer, scanline and tiled, and damage in the part's chunks rejected."""

import struct

import numpy as np
import OpenEXR
import pytest
import torch

import torchgrade as tg
from torchgrade.io.exr import decode
from torchgrade.io.exr.header_bytes import read_headers

BEACHBALL = "formats/beachball_multipart.0001.exr"


def window(x_min, y_min, x_max, y_max):
    return (np.array([x_min, y_min], np.int32), np.array([x_max, y_max], np.int32))


def expected_layer(whole, part, view, layer):
    """What ``read_exr`` returns for a layer, from the library's decode of every part: RGB(A) for a
    colour layer (Y alone as grey, as OpenEXR's RGBA interface gives it), else every channel in name
    order, as float32."""
    names = {letter: name for name, (v, lay, letter) in part.names.items() if (v, lay) == (view, layer)}
    if {"R", "G", "B"} <= names.keys() or names.keys() == {"Y"}:
        letters = [c if c in names else "Y" for c in "RGB"] + [c for c in "A" if c in names]
    else:
        letters = sorted(names)
    channels = whole.parts[part.index].channels
    return torch.stack([torch.from_numpy(channels[names[c]].pixels.astype(np.float32)) for c in letters])


def assert_every_layer_reads_as_the_whole_file_decodes(path, monkeypatch):
    copies = []
    monkeypatch.setattr(decode, "write_single_part", lambda *args: copies.append(args[1].index) or write_single_part(*args))
    whole = OpenEXR.File(str(path), separate_channels=True)
    parts = tg.io.exr_info(path)
    for part in parts:
        for view, layer in sorted(part.layers, key=str):
            image = tg.io.read_exr(path, part=part.index, layer=layer, view=view)
            expected = expected_layer(whole, part, view, layer)
            assert image.shape == expected.shape and torch.equal(image.view(torch.int32), expected.view(torch.int32)), \
                (part.index, view, layer)
    assert set(copies) == {part.index for part in parts[1:]}  # each later part went through a copy of its own


write_single_part = decode.write_single_part


def test_every_part_and_layer_of_the_stereo_frame_reads_as_the_whole_file_decodes(exr_dir, monkeypatch):
    assert_every_layer_reads_as_the_whole_file_decodes(exr_dir / BEACHBALL, monkeypatch)


def write_tiled_parts(path, compression=OpenEXR.ZIP_COMPRESSION):
    """Three tiled parts: RGB half 16×16 tiles; a part mixing half, float and uint channels, its data
    window offset inside a larger display window, 8×4 tiles; and a one-tile Y part."""
    rng = np.random.default_rng(5)

    def tiled(x, y):
        tiles = OpenEXR.TileDescription()
        tiles.xSize, tiles.ySize = x, y
        return {"type": OpenEXR.tiledimage, "tiles": tiles, "compression": compression}

    half = lambda shape: (rng.standard_normal(shape) * 100).astype(np.float16)  # noqa: E731
    frame = {"displayWindow": window(0, 0, 50, 40)}  # parts share their display window
    beauty = {c: half((33, 47)) for c in "RGB"}
    mixed = {"R": half((21, 30)), "G": rng.standard_normal((21, 30)).astype(np.float32), "B": half((21, 30)),
             "A": rng.random((21, 30), np.float32), "Z": rng.random((21, 30), np.float32),
             "id.n": rng.integers(0, 2**32, (21, 30), dtype=np.uint32), "id.w": half((21, 30))}
    OpenEXR.File([OpenEXR.Part({**tiled(16, 16), **frame, "name": "beauty", "dataWindow": window(0, 0, 46, 32)}, beauty),
                  OpenEXR.Part({**tiled(8, 4), **frame, "name": "mixed", "dataWindow": window(-7, 3, 22, 23)}, mixed),
                  OpenEXR.Part({**tiled(64, 64), **frame, "name": "grey", "dataWindow": window(0, 0, 8, 4)}, {"Y": half((5, 9))})]
                 ).write(str(path))


@pytest.mark.parametrize("compression", [OpenEXR.ZIP_COMPRESSION, OpenEXR.NO_COMPRESSION, OpenEXR.PIZ_COMPRESSION,
                                         OpenEXR.RLE_COMPRESSION])
def test_every_part_and_layer_of_a_tiled_mixed_type_file_reads_as_the_whole_file_decodes(tmp_path, monkeypatch, compression):
    write_tiled_parts(tmp_path / "tiled.exr", compression)
    assert [p.kind for p in tg.io.exr_info(tmp_path / "tiled.exr")] == ["tiledimage"] * 3
    assert_every_layer_reads_as_the_whole_file_decodes(tmp_path / "tiled.exr", monkeypatch)


def test_a_later_part_in_the_display_window_is_its_data_window_placed(tmp_path):
    write_tiled_parts(tmp_path / "tiled.exr")
    data = tg.io.read_exr(tmp_path / "tiled.exr", part="mixed")
    framed = tg.io.read_exr(tmp_path / "tiled.exr", part="mixed", window="display")
    # data window x -7..22, y 3..23 in a 51×41 display window: display (x, y) is data (x + 7, y - 3)
    assert framed.shape == (4, 41, 51) and framed[:, :3].eq(0).all() and framed[:, :, 23:].eq(0).all()
    assert torch.equal(framed[:, 3:24, :23], data[:, :, 7:])


def luminance_chroma(size):
    rng = np.random.default_rng(2)
    y, chroma = rng.random(size) * 4 + 0.01, rng.random((2, *size)) - 0.5
    return {"Y": y.astype(np.float16), **{n: OpenEXR.Channel(c.astype(np.float16), 2, 2) for n, c in zip(("RY", "BY"), chroma)}}


def test_a_luminance_chroma_later_part_reads_as_the_same_picture_in_a_file_of_its_own(tmp_path):
    # subsampled channels are decoded whole (OpenEXR.File), from the copy of their part alone
    header = {"compression": OpenEXR.PIZ_COMPRESSION, "type": OpenEXR.scanlineimage}
    picture = luminance_chroma((38, 52))
    OpenEXR.File(header, picture).write(str(tmp_path / "alone.exr"))
    frame = {"displayWindow": window(0, 0, 51, 37)}
    OpenEXR.File([OpenEXR.Part({**header, **frame, "name": "rgb", "dataWindow": window(0, 0, 3, 3)},
                               {c: np.zeros((4, 4), np.float16) for c in "RGB"}),
                  OpenEXR.Part({**header, **frame, "name": "yc", "dataWindow": window(0, 0, 51, 37)}, picture)]
                 ).write(str(tmp_path / "parts.exr"))
    alone, later = tg.io.read_exr(tmp_path / "alone.exr"), tg.io.read_exr(tmp_path / "parts.exr", part="yc")
    assert (alone[0] - alone[2]).abs().max() > 0.1 and torch.equal(alone.view(torch.int32), later.view(torch.int32))


def write_scanline_parts(path):
    """Three parts of 40 rows, ZIP compressed: 3 chunks of 16 rows each."""
    plane = np.add.outer(np.arange(40), np.arange(30)).astype(np.float16)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File([OpenEXR.Part({**header, "name": name}, {c: plane * (i + 1) for c in "RGB"})
                  for i, name in enumerate(("a", "b", "c"))]).write(str(path))


def chunk_table(data, part):
    """Where part ``part``'s offset table lies, and its entries."""
    headers = read_headers(data)
    counts = [struct.unpack_from("<i", data, next(a.value for a in attributes if a.name == "chunkCount"))[0]
              for attributes in headers.parts]
    at = headers.end + 8 * sum(counts[:part])
    return at, list(struct.unpack_from(f"<{counts[part]}Q", data, at))


def damaged(source, target, edit):
    data = bytearray(source.read_bytes())
    edit(data)
    target.write_bytes(bytes(data))
    return target


@pytest.mark.parametrize("damage, message", [
    ("offset past the end", "chunk 1 at offset .* outside"),
    ("offset into the tables", "chunk 1 at offset .* outside"),
    ("another part's chunk", "belongs to part 0"),
    ("size past the end", "runs past the end"),
    ("truncated", "chunk|past the end"),
    ("chunk count", "chunk count|scanline"),
    ("garbled data", "decode|damaged"),
])
def test_damage_in_a_later_parts_chunks_is_a_value_error_naming_the_file(tmp_path, damage, message):
    source = tmp_path / "parts.exr"
    write_scanline_parts(source)
    data = source.read_bytes()
    at, offsets = chunk_table(data, 1)
    _, first_part = chunk_table(data, 0)

    def edit(buffer):
        if damage == "offset past the end":
            struct.pack_into("<Q", buffer, at + 8 * 1, len(data) + 100)
        elif damage == "offset into the tables":
            struct.pack_into("<Q", buffer, at + 8 * 1, at)
        elif damage == "another part's chunk":
            struct.pack_into("<Q", buffer, at + 8 * 1, first_part[1])
        elif damage == "size past the end":  # part number, y, then the size
            struct.pack_into("<i", buffer, offsets[1] + 8, len(data))
        elif damage == "truncated":
            del buffer[offsets[-1] + 6:]
        elif damage == "chunk count":
            headers = read_headers(data)
            count = next(a for a in headers.parts[1] if a.name == "chunkCount")
            struct.pack_into("<i", buffer, count.value, len(offsets) - 1)
        else:  # the ZIP stream of a chunk
            buffer[offsets[1] + 12:offsets[1] + 40] = bytes(range(28))

    broken = damaged(source, tmp_path / "broken.exr", edit)
    with pytest.raises(ValueError, match=rf"broken\.exr: .*({message})"):
        tg.io.read_exr(broken, part="b")
    assert tg.io.read_exr(source, part="b").shape == (3, 40, 30)


def test_copies_leave_no_temporary_file_behind(tmp_path, monkeypatch):
    import tempfile

    write_scanline_parts(tmp_path / "parts.exr")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "scratch"))
    (tmp_path / "scratch").mkdir()
    tg.io.read_exr(tmp_path / "parts.exr", part="c")
    broken = damaged(tmp_path / "parts.exr", tmp_path / "broken.exr", lambda buffer: buffer.__delitem__(slice(-20, None)))
    with pytest.raises(ValueError, match="broken.exr"):
        tg.io.read_exr(broken, part="c")
    assert list((tmp_path / "scratch").iterdir()) == []
