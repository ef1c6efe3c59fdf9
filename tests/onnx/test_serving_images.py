"""The serving example's image files (``examples/serving/images.py``), without a server: sizes read from headers
before decoding, and every malformed, hostile or unsupported file refused with a short ``ValueError`` naming no path
on the server. :data:`HOSTILE` are the files ``test_serving.py`` also sends through the server."""

from __future__ import annotations

import io
import struct
import sys
import tempfile
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg

ROOT = Path(__file__).resolve().parents[2]
EXR_DIR = ROOT.parent / "shared" / "data" / "exr"
sys.path.insert(0, str(ROOT / "examples" / "serving"))

from images import EXR_HEAD_BYTES, check_kind, decode_image, image_header  # noqa: E402

UINT8 = tg.onnx.frame_format(torch.uint8, "NHWC", "srgb8")
UINT16 = tg.onnx.frame_format(torch.uint16, "NHWC", "srgb8")
FLOAT32 = tg.onnx.frame_format(torch.float32, "NHWC", "srgb8")


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def hand_made_png(width: int, height: int, depth: int = 8, colour: int = 2, idat: bytes | None = None) -> bytes:
    """A PNG written by hand from the specification (signature, IHDR, one IDAT, IEND), zero samples unless ``idat``
    is given: headers Pillow would never write."""
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[colour]
    if idat is None:
        idat = zlib.compress(b"".join(b"\0" + bytes(width * channels * depth // 8) for _ in range(height)))
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")


def pillow_png(codes: np.ndarray, mode: str = "RGB") -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(codes, mode).save(out, format="PNG")
    return out.getvalue()


CODES = np.random.default_rng(3).integers(0, 256, (21, 34, 3), dtype=np.uint8)
GOOD = pillow_png(CODES)
HOSTILE = {
    "bomb": (hand_made_png(30000, 30000, idat=zlib.compress(bytes(64))), "pixel budget"),
    "truncated": (GOOD[: len(GOOD) // 2], "could not be decoded"),
    "garbage IDAT": (hand_made_png(34, 21, idat=bytes(np.random.default_rng(4).integers(0, 256, 500, dtype=np.uint8))),
                     "could not be decoded"),
    "0x0": (hand_made_png(0, 0, idat=zlib.compress(b"")), "at least 1x1"),
    "16-bit": (hand_made_png(34, 21, depth=16), "8-bit RGB or RGBA PNGs, got a 16-bit RGB one"),
    "palette": (hand_made_png(34, 21, colour=3), "got a 8-bit palette one"),
    "grey": (pillow_png(CODES[..., 0], "L"), "got a 8-bit grey one"),
    "damaged IHDR": (GOOD[:20] + bytes([GOOD[20] ^ 1]) + GOOD[21:], "sound IHDR"),
    "GIF": (b"GIF89a" + bytes(64), "a PNG or an OpenEXR file"),
    "empty": (b"", "a PNG or an OpenEXR file"),
    "EXR headers only": ((EXR_DIR / "Desk.exr").read_bytes()[:300], "not a readable OpenEXR"),
}
"""Files a server must refuse with 400, each with a part of its message."""


@pytest.mark.parametrize("name", HOSTILE)
def test_hostile_and_unsupported_images_are_refused_with_their_reason(name):
    body, reason = HOSTILE[name]
    with pytest.raises(ValueError, match=reason):
        decode_image(body, FLOAT32, 1 << 22)


def test_the_bomb_is_refused_from_its_header_before_pillow_sees_it():
    body, _ = HOSTILE["bomb"]
    assert len(body) < 100
    with pytest.raises(ValueError) as refused:
        decode_image(body, UINT8, 1 << 26)
    assert "30000x30000" in str(refused.value) and "Decompression" not in str(refused.value)


def test_a_png_goes_to_an_integer_model_as_its_codes_and_to_a_float_one_as_light():
    assert np.array_equal(decode_image(GOOD, UINT8, 1 << 20), CODES)
    assert np.array_equal(decode_image(GOOD, UINT16, 1 << 20), np.round(CODES / 255 * 65535).astype(np.uint16))
    rgba = np.concatenate([CODES, np.full(CODES.shape[:2] + (1,), 7, np.uint8)], axis=2)
    assert np.array_equal(decode_image(pillow_png(rgba, "RGBA"), UINT8, 1 << 20), CODES)  # alpha is left out
    light = decode_image(GOOD, FLOAT32, 1 << 20)
    expected = np.where(CODES / 255 <= 0.04045, CODES / 255 / 12.92, ((CODES / 255 + 0.055) / 1.055) ** 2.4)  # IEC 61966-2-1
    assert light.dtype == np.float32 and np.abs(light - expected).max() < 1e-6


def test_sizes_come_from_the_headers_alone():
    """A PNG's from its first 33 bytes, as Pillow reads it; an EXR's from the first bytes that hold its headers (the
    sample files' data windows, as the OpenEXR bindings read them), ``None`` while they run on."""
    assert image_header(GOOD[:33], complete=False) == ("png", 21, 34)
    assert image_header(GOOD[:20], complete=False) is None
    for name in ("Desk", "GoldenGate", "Garden"):
        data = (EXR_DIR / f"{name}.exr").read_bytes()
        (part,) = tg.io.exr_info(EXR_DIR / f"{name}.exr")
        assert image_header(data[:64], complete=False) is None
        assert image_header(data[:EXR_HEAD_BYTES], complete=False) == ("exr", *part.size())


def test_an_exr_sent_to_a_model_of_codes_is_refused_naming_the_export_that_takes_light():
    exr = (EXR_DIR / "Carrots.exr").read_bytes()
    for fmt in (UINT8, UINT16):
        with pytest.raises(ValueError, match="float input for EXR frames"):
            decode_image(exr, fmt, 1 << 22)
        with pytest.raises(ValueError, match="would clip"):
            check_kind("exr", fmt)
    check_kind("exr", FLOAT32)
    light = decode_image(exr, FLOAT32, 1 << 22)
    assert np.array_equal(light, tg.io.read_exr(EXR_DIR / "Carrots.exr", to_rec709=True)[:3].permute(1, 2, 0).numpy())


@pytest.mark.parametrize("path", sorted((EXR_DIR / "damaged").glob("*_exr")), ids=lambda path: path.name[:24])
def test_damaged_exrs_are_refused_without_naming_a_file_on_the_server(path):
    with pytest.raises(ValueError) as refused:
        decode_image(path.read_bytes(), FLOAT32, 1 << 24)
    message = str(refused.value)
    assert tempfile.gettempdir() not in message and "torchgrade-serve" not in message and "frame.exr" not in message, message


def tiled_exr(height: int, width: int, tile_height: int, dtype=np.float32) -> bytes:
    """An RGBA OpenEXR file of zeros in tiles as wide as the image and ``tile_height`` rows high, written by OpenEXR."""
    import OpenEXR

    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize = width, tile_height
    header = {"type": OpenEXR.tiledimage, "tiles": tiles, "compression": OpenEXR.ZIP_COMPRESSION}
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "tiled.exr"
        OpenEXR.File(header, {name: np.zeros((height, width), dtype) for name in "RGBA"}).write(str(path))
        return path.read_bytes()


def test_an_exr_whose_tiles_are_taller_than_the_image_is_refused_before_it_is_decoded():
    """OpenEXR buffers a row of tiles whatever the image's height: a 563-byte 4096x2 file in tiles 8000 rows high held
    502 MiB as it was read (2 GiB, read_exr's own default budget, for taller tiles), while the server had reserved the
    memory of 8192 pixels. The server reads an EXR within the bytes a pixel of the costliest file it takes may need."""
    from images import EXR_BYTES_PER_PIXEL

    hostile = tiled_exr(2, 4096, 8000)
    assert len(hostile) < 1000
    with pytest.raises(ValueError, match=f"above the budget of {EXR_BYTES_PER_PIXEL * 2 * 4096} bytes") as refused:
        decode_image(hostile, FLOAT32, 1 << 22)
    assert tempfile.gettempdir() not in str(refused.value) and "frame.exr" not in str(refused.value)
    assert decode_image(tiled_exr(2, 4096, 2), FLOAT32, 1 << 22).shape == (2, 4096, 3)  # tiles as tall as the image
