"""The image files the serving example takes, PNG and OpenEXR: their sizes read from their headers before anything is
decoded, then their decoding to the frame a model takes, every failure a short ``ValueError`` that names no file on
the server.

A PNG's size and sample format are in its first 33 bytes (the signature and the ``IHDR`` chunk, whose CRC is checked);
only 8-bit RGB and RGBA are taken. An OpenEXR file's data windows are in its headers, read by torchgrade's own header
reader (:mod:`torchgrade.io.exr.header_bytes`) from the body's first bytes (at most :data:`EXR_HEAD_BYTES`); the
largest part bounds what a read may decode, and a read may take :data:`EXR_BYTES_PER_PIXEL` bytes a pixel at most.
EXR frames are scene-linear light: a model whose input is sRGB codes would clip them at 1.0, so they are refused for
it, naming the export that takes them.
"""

from __future__ import annotations

import io
import struct
import tempfile
import zlib
from pathlib import Path

import numpy as np
import torch

import torchgrade as tg
from torchgrade.base.budget import check_pixels
from frames import pack_frame
from torchgrade.io.exr.header_bytes import HeaderBudgetError, check_required, read_headers, value

__all__ = ["EXR_BYTES_PER_PIXEL", "EXR_HEAD_BYTES", "PNG_HEAD_BYTES", "check_kind", "costliest_exr", "decode_image",
           "encode_png", "image_header", "sample_body"]

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
EXR_MAGIC = b"\x76\x2f\x31\x01"
_IHDR = struct.Struct(">I4sIIBBBBBI")
"""The ``IHDR`` chunk: length (13), type, width, height, bit depth, colour type, compression, filter and interlace
methods, CRC."""
PNG_HEAD_BYTES = len(PNG_SIGNATURE) + _IHDR.size
EXR_HEAD_BYTES = 1 << 20
"""Bytes an OpenEXR file's headers may span here (the sample files' span at most a few KiB)."""
EXR_BYTES_PER_PIXEL = 48
"""Bytes a pixel ``tg.io.read_exr`` may take here (its ``max_bytes``, counted as it counts them: the samples decoded,
the float32 tensor returned, a tiled part's row of tiles): a float RGBA file in tiles no taller than the image
(:func:`costliest_exr`). OpenEXR buffers a row of tiles whatever the image's height, so without this a 563-byte 4096x2
file in tiles 8000 rows high held 502 MiB."""
_COLOUR_TYPES = {0: "grey", 2: "RGB", 3: "palette", 4: "grey and alpha", 6: "RGBA"}
_PNG_ERRORS = (OSError, SyntaxError, ValueError, EOFError, struct.error, zlib.error)
"""What Pillow raises for a damaged, truncated or oversized PNG (``DecompressionBombError`` is added at import)."""


def png_size(head: bytes) -> tuple[int, int]:
    """``(height, width)`` of a PNG from its first :data:`PNG_HEAD_BYTES` bytes; ``ValueError`` unless it is 8-bit RGB
    or RGBA.

    Examples:
        >>> ihdr = b"IHDR" + struct.pack(">IIBBBBB", 640, 480, 16, 2, 0, 0, 0)
        >>> png_size(PNG_SIGNATURE + struct.pack(">I", 13) + ihdr + struct.pack(">I", zlib.crc32(ihdr)))
        Traceback (most recent call last):
        ...
        ValueError: this server takes 8-bit RGB or RGBA PNGs, got a 16-bit RGB one
    """
    if len(head) < PNG_HEAD_BYTES:
        raise ValueError(f"the PNG ends inside its header ({len(head)} bytes)")
    length, kind, width, height, depth, colour, compression, filtering, interlace, crc = _IHDR.unpack_from(head, 8)
    if length != 13 or kind != b"IHDR" or crc != zlib.crc32(head[12:29]):
        raise ValueError("the PNG does not start with a sound IHDR header")
    if depth != 8 or colour not in (2, 6):
        raise ValueError(f"this server takes 8-bit RGB or RGBA PNGs, got a {depth}-bit {_COLOUR_TYPES.get(colour, colour)} one")
    if compression or filtering or interlace > 1:
        raise ValueError("the PNG's header names a compression, filter or interlace method PNG does not have")
    return height, width


def exr_size(head: bytes, complete: bool) -> tuple[int, int] | None:
    """``(height, width)`` of the largest data window in an OpenEXR file's headers, from its first bytes ``head``;
    ``None`` while the headers run past them, unless ``complete`` (no more will come): then ``ValueError``."""
    try:
        headers = read_headers(head)
        check_required(headers, head)
    except HeaderBudgetError as error:
        raise ValueError(f"the OpenEXR headers are too large: {error}") from None
    except (ValueError, IndexError, struct.error) as error:
        if complete:
            raise ValueError(f"not a readable OpenEXR header ({error})") from None
        return None
    windows = [value(head, headers.attributes(index)["dataWindow"]) for index in range(len(headers.parts))]
    return max(((top_y - y + 1, right_x - x + 1) for x, y, right_x, top_y in windows), key=lambda size: size[0] * size[1])


def image_header(head: bytes, complete: bool) -> tuple[str, int, int] | None:
    """``(kind, height, width)`` of the image file whose first bytes are ``head``, kind ``"png"`` or ``"exr"``;
    ``None`` while more bytes are needed, unless ``complete``; ``ValueError`` naming what is wrong.

    Examples:
        >>> image_header(b"GIF89a" + bytes(40), complete=False)
        Traceback (most recent call last):
        ...
        ValueError: an image is a PNG or an OpenEXR file
    """
    if head.startswith(PNG_SIGNATURE):
        return ("png", *png_size(head)) if complete or len(head) >= PNG_HEAD_BYTES else None
    if head.startswith(EXR_MAGIC):
        size = exr_size(head, complete or len(head) >= EXR_HEAD_BYTES)
        return None if size is None else ("exr", *size)
    if not complete and (PNG_SIGNATURE.startswith(head) or EXR_MAGIC.startswith(head)):
        return None
    raise ValueError("an image is a PNG or an OpenEXR file")


def check_kind(kind: str, fmt) -> None:
    """``ValueError`` for an image a model of format ``fmt`` cannot take as it is: scene-linear EXR light for a model
    whose input is sRGB codes."""
    if kind == "exr" and not fmt.input_dtype.is_floating_point:
        code = str(fmt.input_dtype).replace("torch.", "")
        raise ValueError(f"this model takes {code} sRGB codes, which would clip an OpenEXR frame's scene-linear light at "
                         "1.0: serve a model exported with a float input for EXR frames (torchgrade export without "
                         "--input-dtype, or tg.onnx.export(..., input_dtype=torch.float32))")


def _png_codes(body) -> np.ndarray:
    """The ``(height, width, 3)`` uint8 codes of an 8-bit RGB or RGBA PNG."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(body), formats=["PNG"]) as png:
            png.load()
            return np.array(png if png.mode == "RGB" else png.convert("RGB"))  # a copy: writable, as torch wants it
    except _PNG_ERRORS + (Image.DecompressionBombError,) as error:
        raise ValueError(f"the PNG could not be decoded: {str(error)[:200]}") from None


def _exr_linear(body, max_pixels: int, max_bytes: int) -> torch.Tensor:
    """The ``(3, height, width)`` linear Rec.709 light of an OpenEXR file's bytes, read by ``tg.io.read_exr`` (which
    reads files) within its budgets from a private temporary folder whose name no message keeps."""
    with tempfile.TemporaryDirectory(prefix="torchgrade-serve-") as folder:
        path = Path(folder) / "frame.exr"
        path.write_bytes(body)
        try:
            return tg.io.read_exr(path, to_rec709=True, max_pixels=max_pixels, max_bytes=max_bytes)[:3]
        except ValueError as error:
            raise ValueError(str(error).replace(str(path), "the OpenEXR file").replace(folder, "")) from None


def decode_image(body, fmt, max_pixels: int) -> np.ndarray:
    """A PNG or OpenEXR file's bytes as the ``(height, width, 3)`` frame a model of format ``fmt`` takes, its size checked
    from its header against ``max_pixels`` before a pixel is decoded. An 8-bit PNG goes to an integer model as its
    codes (16-bit: ``code * 257``, the same fraction of the top code), to a float one as linear light."""
    kind, height, width = image_header(bytes(body[:EXR_HEAD_BYTES]), complete=True)
    check_pixels(height, width, "an image", max_pixels)
    check_kind(kind, fmt)
    if kind == "png":
        codes = _png_codes(body)
        if fmt.input_dtype == torch.uint8:
            return codes
        if fmt.input_dtype == torch.uint16:
            return codes.astype(np.uint16) * np.uint16(257)
        linear = tg.color.srgb_to_linear(torch.from_numpy(codes).permute(2, 0, 1) / 255.0)
    else:
        linear = _exr_linear(body, max_pixels, EXR_BYTES_PER_PIXEL * height * width)
    return tg.onnx.model_input(linear[None], fmt._replace(layout="NHWC"))[0].numpy()


def encode_png(codes: np.ndarray) -> bytes:
    """A ``(height, width, 3)`` or ``(height, width, 4)`` uint8 array as the bytes of an RGB or RGBA PNG."""
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(codes, "RGB" if codes.shape[2] == 3 else "RGBA").save(out, format="PNG")
    return out.getvalue()


def costliest_exr(linear: torch.Tensor) -> bytes:
    """A ``(3, height, width)`` linear image as the costliest OpenEXR file this server reads for its size (it takes
    :data:`EXR_BYTES_PER_PIXEL`): float RGBA, alpha 1, in one row of tiles as tall as the image."""
    import OpenEXR

    height, width = linear.shape[1:]
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize = width, height
    planes = {name: plane.numpy() for name, plane in zip("RGB", linear.float().contiguous())}
    planes["A"] = np.ones((height, width), np.float32)
    with tempfile.TemporaryDirectory(prefix="torchgrade-serve-") as folder:
        path = Path(folder) / "frame.exr"
        OpenEXR.File({"type": OpenEXR.tiledimage, "tiles": tiles, "compression": OpenEXR.ZIP_COMPRESSION}, planes).write(str(path))
        return path.read_bytes()


def sample_body(kind: str, side: int, fmt) -> bytes:
    """A ``side`` x ``side`` request body of ``kind`` (``"frame"``, ``"png"`` or ``"exr"``) for a model of format
    ``fmt``, the costliest of its kind to decode: ramps of light from 0 to 4, as a raw frame of the model's input, an
    8-bit RGBA PNG of their sRGB codes (its alpha dropped in a copy), or :func:`costliest_exr`."""
    ramp = torch.linspace(0.0, 2.0, side)
    linear = torch.stack([ramp[:, None] * ramp, ramp.flip(0)[:, None] * ramp, ramp[:, None] * ramp.flip(0)])
    if kind == "exr":
        return costliest_exr(linear)
    if kind == "png":
        codes = tg.onnx.model_input(linear[None], tg.onnx.frame_format(torch.uint8, "NHWC"))[0].numpy()
        return encode_png(np.concatenate([codes, np.full_like(codes[..., :1], 255)], axis=2))
    return pack_frame(tg.onnx.model_input(linear[None], fmt._replace(layout="NHWC"))[0].numpy())
