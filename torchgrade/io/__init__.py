"""File interchange: OpenEXR images and .cube LUTs."""

from .exr import read_exr, write_exr
from .cube import read_cube, write_cube
