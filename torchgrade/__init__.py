"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs).

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> look = tg.PostFX(grade={"contrast": 20}, tonemap="neutral")
    >>> look(torch.rand(1, 3, 8, 8) * 4).shape
    torch.Size([1, 3, 8, 8])
"""

from . import catalog, color, core, curves, functional, io, onnx, scene
from .augment import RandomPostFX
from .bloom import Bloom, ConvolutionBloom
from .display import Display
from .dither import Dither
from .exposure import AutoExposure
from .grade import ColorGrade
from .lut import LUT3D, bake_lut
from .match import match_look
from .pipeline import PostFX
from .primary import PrimaryGrade
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
    "scene",
    "RandomPostFX",
    "Bloom",
    "ConvolutionBloom",
    "Dither",
    "Display",
    "AutoExposure",
    "ColorGrade",
    "LUT3D",
    "bake_lut",
    "match_look",
    "PostFX",
    "PrimaryGrade",
    "TONEMAP_MODES",
    "ToneMap",
]
