"""3D LUTs: bake any per-pixel transform into a lattice, apply it with trilinear or tetrahedral interpolation.

The package holds one family per file:

* :mod:`~torchgrade.lut.shapers`: the 1D shapers before the lattice (:data:`SHAPERS`), each with
  its encoding, default domain and ``.cube`` form (the default for HDR looks, ``"logc_hdr"``, is LogC
  to linear 58.86 and a tail to 65504 on the last lattice planes);
* :mod:`~torchgrade.lut.kernels`: the interpolations (:data:`KERNELS`), each with its gather form
  and its ``GridSample`` graph forms by export backend;
* :mod:`~torchgrade.lut.lattice`: sizes, lattice coordinates, table layouts, domains;
* :mod:`~torchgrade.lut.apply`: :class:`LUT3D` (a :class:`~torchgrade.base.stage.Stage`), its lookup
  and compile cache, and :class:`LUTLookup`, its ONNX export form;
* :mod:`~torchgrade.lut.fit`: :func:`fit_shaper` and :func:`fit_scene_shaper`, per-channel shapers fitted to a
  transform or to a scene;
* :mod:`~torchgrade.lut.validation` and :mod:`~torchgrade.lut.report`: the colours every baked LUT
  is measured on, and its :class:`ErrorReport`;
* :mod:`~torchgrade.lut.bake`: :func:`bake_lut`, automatic sizing.

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> lut = tg.bake_lut(lambda image: image.clamp(0, 1) ** 2, size=9)
    >>> round(float(lut(torch.full((1, 3, 1, 1), 0.5), "trilinear").mean()), 2)
    0.25
"""

from .bake import AUTO_SIZES, bake_lut, expects_hdr, is_display_referred, scene_domain, srgb_code_error
from .entries import ANCHOR_WEIGHT, ENTRY_CHOICES, SCENE_WEIGHT, display_miss, fit_entries, fitting_colours, scene_pixels
from .fit import FIT_KNOTS, SCENE_FIT_WEIGHT, fit_scene_shaper, fit_shaper
from .kernels import (BACKENDS, INTERPOLATIONS, KERNELS, LUT_BACKENDS, Kernel, strip_table, tetrahedral, trilinear,
                      trilinear_grid_sample, trilinear_strip, trilinear_strip_lookup)
from .lattice import MAX_SIZE, MIN_SIZE, check_size, checked_domain, identity_table, lattice, planar_table
from .layer import LUT3D, LUTLookup
from .apply import (
    OUTPUT_ENCODINGS,
    apply_lut,
    compiled_lookup,
    decode_output,
    encode_output,
    chunked_lookup,
    lookup,
    table_output,
)
from .report import ErrorReport, LUTAccuracyWarning, code_errors
from .shapers import (DEFAULT_DOMAINS, LOGC_BLACK, LOGC_HALF_MAX, LOGC_TOP, SHAPERS, CurveShaper, FittedShaper, LinearShaper,
                      LogCHDRShaper, LogCShaper, Shaper, lattice_unit, sample_curve, shaper_decode, shaper_encode)
from .validation import realistic_colours, validation_colours


__all__ = [
    "AUTO_SIZES", "bake_lut", "expects_hdr", "is_display_referred", "scene_domain", "srgb_code_error",
    "BACKENDS", "INTERPOLATIONS", "KERNELS", "LUT_BACKENDS", "Kernel", "strip_table", "tetrahedral", "trilinear",
    "trilinear_grid_sample", "trilinear_strip", "trilinear_strip_lookup",
    "MAX_SIZE", "MIN_SIZE", "check_size", "checked_domain", "identity_table", "lattice", "planar_table",
    "LUT3D", "OUTPUT_ENCODINGS", "LUTLookup", "apply_lut", "compiled_lookup", "decode_output", "encode_output",
    "lookup", "chunked_lookup", "table_output",
    "DEFAULT_DOMAINS", "LOGC_BLACK", "LOGC_HALF_MAX", "LOGC_TOP", "SHAPERS", "CurveShaper", "LinearShaper", "LogCShaper",
    "LogCHDRShaper", "Shaper", "lattice_unit",
    "sample_curve", "shaper_decode", "shaper_encode", "FittedShaper",
    "ENTRY_CHOICES", "fit_entries", "fitting_colours", "display_miss", "ANCHOR_WEIGHT", "SCENE_WEIGHT",
    "scene_pixels", "FIT_KNOTS", "SCENE_FIT_WEIGHT", "fit_scene_shaper", "fit_shaper", "ErrorReport", "LUTAccuracyWarning", "code_errors", "validation_colours",
    "realistic_colours",
]
