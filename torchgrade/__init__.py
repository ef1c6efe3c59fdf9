"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs)."""

from . import color, core, functional, io
from .grade import ColorGrade
from .tonemap import ToneMap, TONEMAP_MODES

__version__ = "0.1.0"
