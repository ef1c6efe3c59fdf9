"""OpenEXR reading and writing through the OpenEXR 3.x bindings (``OpenEXR.File``).

Files are untrusted input: the header is read on its own first and the declared image size is
bounded before any pixel is decoded; any decoding failure is reported as ``ValueError`` naming the
file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import torch

from ..color import primaries_to_rec709_matrix
from ..core import apply_matrix, check_image
from .atomic import atomic_write

MAX_PIXELS = 1 << 28
"""Largest image read_exr accepts (268 megapixels): bounds memory before decoding."""


def _header(path: Path) -> dict:
    try:
        return OpenEXR.File(str(path), header_only=True).header()
    except Exception as error:  # the bindings raise RuntimeError/OSError/ValueError for damaged files
        raise ValueError(f"{path}: not a readable OpenEXR file ({error})") from None


def _checked_size(path: Path, header: dict) -> tuple[int, int]:
    (x_min, y_min), (x_max, y_max) = header["dataWindow"]
    width, height = int(x_max) - int(x_min) + 1, int(y_max) - int(y_min) + 1
    if width <= 0 or height <= 0 or width * height > MAX_PIXELS:
        raise ValueError(f"{path}: data window {width}x{height} is empty or larger than {MAX_PIXELS} pixels")
    return height, width


def _planes(path: Path, channels: dict, shape: tuple[int, int]) -> list[np.ndarray]:
    """The image as RGB or RGBA planes.

    As OpenEXR's own RGBA interface does, a file with some of R, G, B gets zeros for the missing
    ones, and a luminance-only (Y) file becomes grey RGB.
    """
    planes = {}
    for name, channel in channels.items():
        pixels = np.asarray(channel.pixels)
        if pixels.ndim == 3:
            planes.update({letter: pixels[..., i] for i, letter in enumerate(name)})
        else:
            planes[name.split(".")[-1]] = pixels
    if any(c in planes for c in "RGB"):
        zeros = np.zeros(shape, dtype=np.float32)
        colour = [planes.get(c, zeros) for c in "RGB"]
    elif "Y" in planes:
        colour = [planes["Y"]] * 3
    else:
        raise ValueError(f"{path}: no R, G, B or Y channels (found {sorted(channels)})")
    result = colour + ([planes["A"]] if "A" in planes else [])
    if any(p.shape != shape for p in result):
        raise ValueError(f"{path}: channel sizes {[p.shape for p in result]} do not match the data window {shape}")
    return result


def read_exr(path, to_rec709: bool = False) -> torch.Tensor:
    """Read an OpenEXR image as a float32 tensor ``(3, H, W)`` (RGB) or ``(4, H, W)`` (RGBA).

    Half and float files are accepted; luminance-only files become grey RGB. Alpha is returned as
    stored (OpenEXR alpha is premultiplied). With ``to_rec709=True`` a file whose ``chromaticities``
    attribute names other primaries (ACES AP0, say) is converted to linear Rec.709 with a Bradford
    adaptation to D65; files without the attribute are Rec.709 by the OpenEXR convention.
    Raises ``ValueError`` for damaged or unsupported files.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such EXR file: {path}")
    header = _header(path)
    shape = _checked_size(path, header)
    try:
        channels = OpenEXR.File(str(path)).channels()
    except Exception as error:
        raise ValueError(f"{path}: cannot decode OpenEXR pixels ({error})") from None
    image = torch.from_numpy(np.stack([p.astype(np.float32) for p in _planes(path, channels, shape)]))
    if to_rec709 and header.get("chromaticities") is not None:
        image[:3] = _to_rec709(image[:3], header["chromaticities"])
    return image


def _to_rec709(rgb: torch.Tensor, chromaticities) -> torch.Tensor:
    """Convert RGB with the header's chromaticities ``(xr, yr, xg, yg, xb, yb, xw, yw)`` to Rec.709."""
    pairs = tuple(zip(chromaticities[0::2], chromaticities[1::2]))
    return apply_matrix(primaries_to_rec709_matrix(pairs).float(), rgb)


def write_exr(path, image: torch.Tensor, half: bool = True) -> None:
    """Write a ``(3, H, W)`` or ``(4, H, W)`` linear image as an OpenEXR file (half floats by default).

    The file is written to a temporary name and renamed, so a failed write leaves nothing behind.
    """
    if isinstance(image, torch.Tensor) and image.dim() == 3 and image.shape[0] == 4:
        check_image(image[:3])
    else:
        check_image(image)
        if image.dim() != 3:
            raise ValueError(f"write_exr takes one image (3, H, W) or (4, H, W), got shape {tuple(image.shape)}")
    dtype = np.float16 if half else np.float32
    pixels = image.detach().cpu().float().numpy()
    if half:
        pixels = np.clip(np.nan_to_num(pixels, nan=0.0), -65504.0, 65504.0)
    name = "RGBA" if image.shape[0] == 4 else "RGB"
    data = np.ascontiguousarray(pixels.transpose(1, 2, 0).astype(dtype))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    atomic_write(path, lambda temporary: OpenEXR.File(header, {name: data}).write(temporary))
