"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs).

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> look = tg.PostFX(grade={"contrast": 20}, tonemap="neutral")
    >>> look(torch.rand(1, 3, 8, 8) * 4).shape
    torch.Size([1, 3, 8, 8])
"""

import importlib

from . import augment_saved  # noqa: F401  registers what torch.load(weights_only=True) of a RandomPostFX needs, without kornia
from . import color, core, curves, functional, runtime, scene
from .bloom import Bloom, ConvolutionBloom
from .display import Display
from .dither import Dither
from .exposure import AutoExposure
from .grade import ColorGrade
from .look_lut import LookLUT
from .lut import LUT3D, bake_lut
from .match import match_look
from .pipeline import PostFX
from .primary import PrimaryGrade
from .runtime import compile
from .tonemap import TONEMAP_MODES, ToneMap

__version__ = "0.1.0"

__all__ = [
    "catalog",
    "color",
    "core",
    "curves",
    "functional",
    "io",
    "onnx",
    "runtime",
    "scene",
    "compile",
    "RandomPostFX",
    "Bloom",
    "ConvolutionBloom",
    "Dither",
    "Display",
    "AutoExposure",
    "ColorGrade",
    "LUT3D",
    "LookLUT",
    "bake_lut",
    "match_look",
    "PostFX",
    "PrimaryGrade",
    "TONEMAP_MODES",
    "ToneMap",
]


_LAZY_MODULES = ("catalog", "io", "onnx")
"""Subpackages imported at their first use: the onnx, OpenEXR and numpy packages behind them take longer to
import than torchgrade itself (``import torchgrade`` stays within 0.3 s of ``import torch``)."""


def __getattr__(name: str):
    if name in _LAZY_MODULES:
        return importlib.import_module(f".{name}", __name__)
    # RandomPostFX is built on kornia's augmentation base, and kornia takes longer to import than torchgrade:
    # it is imported at the first use of the name.
    if name == "RandomPostFX":
        from .augment import RandomPostFX

        globals()[name] = RandomPostFX
        return RandomPostFX
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
