"""OpenEXR reading and writing through the OpenEXR 3.x bindings (``OpenEXR.File``).

Files are untrusted input: the headers are read on their own first (:func:`exr_info`), and before
any pixel is decoded, from the file's bytes, a read refuses deep files, headers that lack an
attribute the format requires, chunk offset tables the library could not follow soundly, and files
whose decoding would pass the pixel or byte budget (tiles and display window included); damage the
library still meets while decoding rejects the file too, with a ``ValueError`` naming it.
"""

from .chromaticities import ADAPTATIONS
from .decode import MAX_BYTES, MAX_PIXELS
from .layout import ExrPart, exr_info
from .read import read_exr
from .write import write_exr

__all__ = ["ADAPTATIONS", "MAX_BYTES", "MAX_PIXELS", "ExrPart", "exr_info", "read_exr", "write_exr"]
