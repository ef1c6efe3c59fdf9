"""File interchange: OpenEXR images, .cube and CLF LUTs."""

from .clf import read_clf, write_clf
from .cube import read_cube, write_cube
from .exr import ExrPart, exr_info, read_exr, write_exr

__all__ = ["ExrPart", "exr_info", "read_clf", "read_cube", "read_exr", "write_clf", "write_cube", "write_exr"]
