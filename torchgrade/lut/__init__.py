"""3D LUTs: bake any per-pixel transform into a lattice, apply it with trilinear or tetrahedral interpolation.

The package holds one family per file:

* :mod:`~torchgrade.lut.shapers`: the 1D shapers before the lattice (:data:`SHAPERS`), each with
  its encoding, default domain and ``.cube`` form (the default for HDR looks, ``"logc_extended"``, is the
  ``"logc"`` lattice to linear 58.86 and a tail to 65504 on 12 more planes);
* :mod:`~torchgrade.lut.kernels`: the interpolations (:data:`KERNELS`), each with its gather form
  and its ``GridSample`` graph forms by export backend;
* :mod:`~torchgrade.lut.operator`: the operator ``torchgrade::lut_lookup`` the CPU looks up with, over the C loop
  built with the package (``lookup.c``);
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

from .bake import AUTO_SIZES, bake_lut, srgb_code_error
from .entries import ENTRY_CHOICES, fit_entries
from .fit import fit_scene_shaper, fit_shaper
from .backends import BACKENDS, LUT_BACKENDS
from .kernels import INTERPOLATIONS, KERNELS, Kernel
from .lattice import MAX_SIZE, MIN_SIZE, identity_table, lattice
from .layer import LUT3D
from .apply import OUTPUT_ENCODINGS, apply_lut
from .report import ErrorReport, LUTAccuracyWarning, code_errors
from .shapers import DEFAULT_DOMAINS, SHAPERS, Shaper
from .validation import realistic_colours, validation_colours


__all__ = [
    "LUT3D", "bake_lut", "apply_lut", "identity_table", "lattice", "fit_entries", "fit_shaper", "fit_scene_shaper",
    "ErrorReport", "LUTAccuracyWarning", "code_errors", "srgb_code_error", "realistic_colours",
    "validation_colours", "INTERPOLATIONS", "KERNELS", "Kernel", "BACKENDS", "LUT_BACKENDS", "SHAPERS", "Shaper",
    "DEFAULT_DOMAINS", "OUTPUT_ENCODINGS", "ENTRY_CHOICES", "AUTO_SIZES", "MIN_SIZE", "MAX_SIZE",
]
"""The names a user calls. The package also imports its building blocks (kernels, lattice helpers, the lookup's
pieces, shaper classes, fitting weights) for its modules, the ONNX export and the tests; they are not part of the
API contract: import them from their modules."""
