"""``LookLUT``: a creative 3D LUT on the tone-mapped image, with a contribution, as Unity URP's Color Lookup.

A colourist's show LUT (a ``.cube`` or CLF file), a LUT made in a grading application, or any
``(S, S, S, 3)`` table, applied to display-referred light after tone mapping. Unity URP's HDR grading
path (``ApplyColorGrading`` in URP's ``Common.hlsl``) defines it: clamp the tone-mapped colour to [0, 1],
encode it as sRGB, look it up, blend with the contribution in sRGB codes and decode::

    c = sRGB(clamp(x, 0, 1))
    y = sRGB⁻¹(clamp(c + contribution · (LUT(c) - c), 0, 1))

``encoding="linear"`` looks the display-linear values up directly (a LUT authored for linear input).
Unreal's Color Grading LUT with its intensity is the same blend. The LUT is a
:class:`~torchgrade.LUT3D` stage, so its interpolation (a control of the LUT) and its ONNX forms are the
baked LUT's.

Examples:
    >>> import torch
    >>> from torchgrade import LookLUT
    >>> from torchgrade.lut import identity_table
    >>> warm = identity_table(9) * torch.tensor([1.0, 0.9, 0.8])  # a table that cools nothing and warms everything
    >>> look = LookLUT(warm, contribution=0.5)
    >>> out = look(torch.full((1, 3, 1, 1), 0.5))
    >>> out[0, 0, 0, 0].item() > out[0, 2, 0, 0].item()
    True
"""

from __future__ import annotations

from pathlib import Path

import torch

from ..base.images import check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import Param, scalar_param
from ..color import linear_to_srgb, srgb_to_linear
from ..lut import LUT3D

__all__ = [ "look_lut", "LOOK_ENCODINGS", "read_lut_file"]

LOOK_ENCODINGS = ("srgb", "linear")
"""How the display-referred image is encoded for the LUT: sRGB codes (Unity URP, most show LUTs) or display-linear."""


def look_lut(image: torch.Tensor, lookup, contribution: Param = 1.0, encoding: str = "srgb", *, nan_free: bool = False) -> torch.Tensor:
    """Apply a creative LUT ``lookup`` (a :class:`~torchgrade.LUT3D`, or its export form) to display-referred
    ``image`` with ``contribution`` in [0, 1] (a number or per sample ``(B,)``); see the module docstring.
    ``nan_free``: the caller knows ``image`` holds no NaN (:func:`~torchgrade.base.images.sanitize`).

    Examples:
        >>> from torchgrade.lut import LUT3D, identity_table
        >>> image = torch.rand(2, 3, 4, 4)
        >>> torch.allclose(look_lut(image, LUT3D(identity_table(5))), image, atol=1e-6)  # the identity LUT
        True
        >>> torch.allclose(look_lut(image, LUT3D(identity_table(5) * 0.5), contribution=0.0), image, atol=1e-6)  # no blend
        True
    """
    check_image(image)
    x = sanitize(working_dtype(image), nan_free=nan_free).clamp(0.0, 1.0)
    coded = linear_to_srgb(x) if encoding == "srgb" else x
    amount = scalar_param(contribution, coded, "contribution")
    blended = (coded + amount * (lookup(coded) - coded)).clamp(0.0, 1.0)
    return to_input_dtype(srgb_to_linear(blended) if encoding == "srgb" else blended, image)


def read_lut_file(path) -> LUT3D:
    """A ``.cube`` or CLF (``.clf``, ``.ctf``-free) file as a :class:`~torchgrade.LUT3D`, chosen by its suffix.

    Examples:
        >>> read_lut_file("look.png")
        Traceback (most recent call last):
        ...
        ValueError: a look LUT is a .cube or .clf file, got 'look.png'
    """
    suffix = Path(path).suffix.lower()
    if suffix not in (".cube", ".clf"):
        raise ValueError(f"a look LUT is a .cube or .clf file, got {str(path)!r}")
    # torchgrade.io imports OpenEXR, which takes longer to import than torchgrade: it is imported when a file is read.
    from ..io import read_clf, read_cube

    return read_cube(path) if suffix == ".cube" else read_clf(path)
