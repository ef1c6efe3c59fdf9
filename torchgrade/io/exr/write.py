"""``write_exr``: a linear RGB(A) tensor as a single-part OpenEXR file, written atomically."""

from __future__ import annotations

import numpy as np
import torch

from ...base.images import check_image
from ..atomic import atomic_write

__all__ = ["write_exr"]


def _write(channels: dict, temporary: str) -> None:
    import OpenEXR  # the bindings load at the first write, not with torchgrade.io

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    try:
        OpenEXR.File(header, channels).write(temporary)
    except RuntimeError as error:  # the bindings report a failed write (a full disk, say) as RuntimeError
        raise OSError(f"cannot write {temporary}: {error}") from None


def write_exr(path, image: torch.Tensor, half: bool = True) -> None:
    """Write a ``(3, H, W)`` or ``(4, H, W)`` linear image as an OpenEXR file (half floats by default).

    Half output bounds values to ±65504 and writes NaN as 0. The file appears complete or not at
    all (see :func:`torchgrade.io.atomic.atomic_write`); an I/O failure raises ``OSError``.

    Examples:
        >>> import pathlib, tempfile
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "grey.exr"
        >>> write_exr(path, torch.full((3, 2, 2), 0.18))
        >>> path.stat().st_size > 0
        True
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
    atomic_write(path, lambda temporary: _write({name: data}, temporary))
