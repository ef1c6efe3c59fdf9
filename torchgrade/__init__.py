"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs)."""

from . import color, core, functional, io, scene
from .grade import ColorGrade
from .bloom import Bloom
from .exposure import AutoExposure
from .tonemap import ToneMap, TONEMAP_MODES
from .augment import RandomPostFX

__version__ = "0.1.0"
from .lut import LUT3D, bake_lut
from .pipeline import PostFX
from . import onnx
