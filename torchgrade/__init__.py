"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs)."""

from . import color, core, curves, functional, io, onnx, scene
from .augment import RandomPostFX
from .bloom import Bloom, ConvolutionBloom
from .dither import Dither
from .exposure import AutoExposure
from .grade import ColorGrade
from .lut import LUT3D, bake_lut
from .pipeline import PostFX
from .primary import PrimaryGrade
from .tonemap import TONEMAP_MODES, ToneMap

__version__ = "0.1.0"
