"""File interchange: OpenEXR images, .cube and CLF LUTs, compiled graphs."""

from .clf import read_clf, write_clf
from .compile_cache import load_compile_cache, save_compile_cache
from .cube import read_cube, write_cube
from .exr import ExrPart, exr_info, read_exr, write_exr

__all__ = ["ExrPart", "exr_info", "load_compile_cache", "read_clf", "read_cube", "read_exr", "save_compile_cache",
           "write_clf", "write_cube", "write_exr"]
