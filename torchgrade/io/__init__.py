"""File interchange: OpenEXR images and .cube LUTs."""

from .cube import read_cube, write_cube
from .exr import ExrPart, exr_info, read_exr, write_exr

__all__ = ["ExrPart", "exr_info", "read_cube", "read_exr", "write_cube", "write_exr"]
