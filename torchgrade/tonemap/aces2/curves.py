"""ACES 2.0 as tone mapping modes: the SDR 100-nit Rec.709 output and the HDR Rec.2100 output.

Both wrap :func:`~torchgrade.tonemap.aces2.aces2_output` (the Academy's ACES 2.0 Output Transform,
within 0.02 8-bit codes of OpenColorIO 2.6's builtin views on the sample images; see
``tests/tonemap/test_aces2.py``). Unlike the fits, they have no 60 ceiling: the transform takes every
value the non-finite policy lets through and handles out-of-gamut colours itself.
"""

from __future__ import annotations

import torch

from .transform import aces2_output
from .transform import Prepared, peak_number, prepare_output

__all__ = ["aces2_sdr", "aces2_hdr", "prepare_aces2_sdr", "prepare_aces2_hdr", "ACES2_HDR_RANGES"]

ACES2_HDR_RANGES = {"peak_luminance": (100.0, 10000.0)}
"""Peak luminance of the HDR display in cd/m²: the range the ACES 2.0 tonescale is defined for."""


def aces2_sdr(image: torch.Tensor, clip: bool = True, *, nan_free: bool = False, planes: bool = False) -> torch.Tensor:
    """ACES 2.0 "SDR 100 nits (Rec.709)": display-linear Rec.709 in [0, 1] (1.0 = 100 cd/m²).

    Encode with BT.1886 (``x ** (1 / 2.4)``) to get OpenColorIO's "Rec.1886 Rec.709 - Display"
    values, or with sRGB for an sRGB monitor. ``clip`` changes nothing: the transform's output lies in [0, 1].
    ``nan_free``: the caller knows ``image`` holds no NaN (:func:`~torchgrade.base.images.sanitize`); ``planes``: computed
    on the image's planes (:func:`~torchgrade.tonemap.aces2.aces2_output`).

    Examples:
        >>> grey = torch.full((1, 3, 1, 1), 0.18)
        >>> round(float(aces2_sdr(grey)[0, 0, 0, 0] ** (1 / 2.4)), 3)  # OpenColorIO: 0.3831
        0.383
    """
    return aces2_output(image, nan_free=nan_free, planes=planes)  # display-linear in [0, 1] already: clipped or not, the same values


def aces2_hdr(image: torch.Tensor, peak_luminance: float = 1000.0, clip: bool = True, *, nan_free: bool = False,
              planes: bool = False) -> torch.Tensor:
    """ACES 2.0 HDR output for a ``peak_luminance`` cd/m² display, limited to P3-D65, in Rec.2020 primaries.

    Returns display-linear **Rec.2020** values in [0, 1] with 1.0 = ``peak_luminance`` (OpenColorIO's
    "ACES 2.0 - HDR 1000 nits (P3 D65)" view at 1000); encode for a Rec.2100 PQ display with
    ``torchgrade.color.linear_to_pq(x, reference=peak_luminance)``. ``nan_free`` and ``planes`` as :func:`aces2_sdr`'s.

    Examples:
        >>> grey = torch.full((1, 3, 1, 1), 0.18)
        >>> round(float(aces2_hdr(grey)[0, 1, 0, 0]) * 1000.0, 1)  # cd/m²
        14.5
    """
    return aces2_output(image, peak_luminance, "p3_d65", "rec2020", nan_free=nan_free, planes=planes)  # in [0, 1] already, as aces2_sdr


def prepare_aces2_sdr() -> Prepared:
    """Build the SDR transform's gamut tables (once), so a compiled or traced forward holds them as constants; they
    stay built while the returned :class:`~torchgrade.tonemap.aces2.transform.Prepared` is kept."""
    return prepare_output(100.0, "rec709")


def prepare_aces2_hdr(peak_luminance=1000.0) -> Prepared:
    """Build the HDR transform's gamut tables for ``peak_luminance`` (once), as :func:`prepare_aces2_sdr`."""
    return prepare_output(peak_number(peak_luminance), "p3_d65")
