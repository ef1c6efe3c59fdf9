"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs)."""

from . import color, core, functional, io, scene
from .grade import ColorGrade
from .exposure import AutoExposure
from .tonemap import ToneMap, TONEMAP_MODES

__version__ = "0.1.0"
