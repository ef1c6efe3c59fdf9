"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs).

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> look = tg.PostFX(grade={"contrast": 20}, tonemap="neutral")
    >>> look(torch.rand(1, 3, 8, 8) * 4).shape
    torch.Size([1, 3, 8, 8])
"""

import importlib

from . import augment, color, functional, runtime, scene
from .bloom import Bloom, ConvolutionBloom
from .exposure import AutoExposure
from .grading import ColorGrade, PrimaryGrade
from .look import PostFX
from .lut import LUT3D, bake_lut
from .match import match_look
from .output import Display, Dither, LookLUT
from .runtime import compile
from .tonemap import TONEMAP_MODES, ToneMap

__version__ = "0.1.0"

__all__ = [
    "augment",
    "bloom",
    "color",
    "exposure",
    "functional",
    "grading",
    "io",
    "look",
    "lut",
    "match",
    "onnx",
    "output",
    "runtime",
    "scene",
    "tonemap",
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


_LAZY_MODULES = ("io", "onnx", "testing", "integrations")
"""Subpackages imported at their first use, so that ``import torchgrade`` loads none of the onnx, OpenEXR and numpy
packages behind them (``benchmarks/results/import.md``: what the import loads, and its time)."""


def __getattr__(name: str):
    if name in _LAZY_MODULES:
        return importlib.import_module(f".{name}", __name__)
    if name == "RandomPostFX":  # built on kornia, which takes longer to import than torchgrade: imported at first use
        return augment.RandomPostFX
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
