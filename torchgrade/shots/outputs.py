"""The image files a graded shot is written to (``torchgrade grade``, :mod:`torchgrade.integrations.ray`): sRGB PNG (8 or 16 bits), TIFF (16-bit sRGB or 32-bit float linear) and
linear OpenEXR, display-referred or, before tone mapping, scene-referred.

Pillow writes 16-bit PNG only in greyscale, so 16-bit RGB PNG goes through ``pypng`` and TIFF through
``tifffile`` (both in the ``torchgrade[formats]`` extra, imported only when such a file is asked for).

Examples:
    >>> check_output("shot.%04d.tif", bit_depth=None, scene_referred=False)
    '16'
    >>> check_output("shot.png", bit_depth="float", scene_referred=False)
    Traceback (most recent call last):
    ...
    ValueError: --bit-depth float does not fit .png; .png takes 8, 16
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ..base.images import sanitize
from ..color import linear_to_srgb
from ..io import write_exr
from ..io.atomic import atomic_write
__all__ = ["BIT_DEPTHS", "check_output", "write_frame", "display_codes", "write_png"]

def display_codes(image: torch.Tensor, maximum: int, encoded: bool = False) -> np.ndarray:
    """Integer codes ``(H, W, 3)`` in ``[0, maximum]``: of a display signal as it is (``encoded``), else of
    display-referred linear light, sRGB-encoded.

    Examples:
        >>> display_codes(torch.full((3, 1, 1), 0.5), 255, encoded=True).ravel().tolist()
        [128.0, 128.0, 128.0]
    """
    signal = image.clamp(0.0, 1.0) if encoded else linear_to_srgb(image.clamp(0.0, 1.0))
    return np.ascontiguousarray((signal * maximum).round().permute(1, 2, 0).cpu().numpy())


def write_png(path, image: torch.Tensor, encoded: bool = False) -> None:
    """Write a ``(3, H, W)`` image as an 8-bit PNG (atomically): sRGB-encoded light, or a display signal as it is.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> from PIL import Image
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     write_png(Path(folder) / "grey.png", torch.full((3, 2, 4), 0.18))
        ...     with Image.open(Path(folder) / "grey.png") as png:
        ...         png.size, png.getpixel((0, 0))   # linear 0.18 is sRGB code 118
        ((4, 2), (118, 118, 118))
    """
    from PIL import Image

    pixels = display_codes(image, 255, encoded).astype(np.uint8)
    atomic_write(path, lambda temporary: Image.fromarray(pixels, "RGB").save(temporary, format="PNG"))



BIT_DEPTHS = {".png": ("8", "16"), ".tif": ("16", "float"), ".tiff": ("16", "float"), ".exr": ("half", "float")}
"""The sample formats each output extension takes, its default first."""


def check_output(path, bit_depth: str | None, scene_referred: bool) -> str:
    """The bit depth ``path`` will be written with; ``ValueError`` for an extension, depth or space it cannot hold.

    Examples:
        >>> check_output("graded.exr", None, scene_referred=True), check_output("graded.png", "16", scene_referred=False)
        ('half', '16')
    """
    suffix = Path(path).suffix.lower()
    if suffix not in BIT_DEPTHS:
        raise ValueError(f"output must end in .png or .exr, or .tif/.tiff, got {path}")
    depths = BIT_DEPTHS[suffix]
    depth = depths[0] if bit_depth is None else bit_depth
    if depth not in depths:
        raise ValueError(f"--bit-depth {depth} does not fit {suffix}; {suffix} takes {', '.join(depths)}")
    if scene_referred and depth not in ("half", "float"):
        raise ValueError(f"--scene-referred values exceed 1: write them to .exr or a float .tif, not {suffix} at {depth} bits")
    return depth


def _write_png16(path: Path, image: torch.Tensor, encoded: bool) -> None:
    import png

    codes = display_codes(image, 65535, encoded).astype(np.uint16)
    height, width = codes.shape[:2]
    writer = png.Writer(width, height, greyscale=False, bitdepth=16)
    rows = codes.reshape(height, width * 3)
    atomic_write(path, lambda temporary: _save_with(temporary, lambda file: writer.write(file, rows)))


def _save_with(temporary, write) -> None:
    with open(temporary, "wb") as file:
        write(file)


def _write_tiff(path: Path, image: torch.Tensor, depth: str, encoded: bool) -> None:
    import tifffile

    if depth == "float":
        pixels = np.ascontiguousarray(image.detach().float().permute(1, 2, 0).cpu().numpy())
    else:
        pixels = display_codes(image, 65535, encoded).astype(np.uint16)
    atomic_write(path, lambda temporary: tifffile.imwrite(temporary, pixels, photometric="rgb"))


def write_frame(path, image: torch.Tensor, depth: str, encoded: bool = False) -> None:
    """Write a ``(3, H, W)`` linear image to ``path`` in the format its extension and ``depth`` name.

    Integer formats (PNG, 16-bit TIFF) hold sRGB-encoded light clamped to [0, 1], or with ``encoded`` a
    display's signal (:class:`~torchgrade.output.layer.Display`) as it is; EXR and float TIFF hold the values as they are.
    Every format gets the non-finite policy's values (:func:`~torchgrade.base.images.sanitize`: NaN 0, ±Inf ±65504): a look
    that changes nothing (no stage built) would otherwise write the input's NaN and Inf as they are.

    Examples:
        >>> import tempfile
        >>> from torchgrade.io import read_exr
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     write_frame(Path(folder) / "hdr.exr", torch.full((3, 2, 2), 40.0), "float")
        ...     read_exr(Path(folder) / "hdr.exr").max().item()   # scene-referred values kept as they are
        40.0
    """
    path = Path(path)
    suffix = path.suffix.lower()
    image = sanitize(image)
    if suffix == ".exr":
        write_exr(path, image, half=depth == "half")
    elif suffix == ".png":
        write_png(path, image, encoded) if depth == "8" else _write_png16(path, image, encoded)
    else:
        _write_tiff(path, image, depth, encoded)
