"""Unity's HDR output mapping for the Neutral tone mapper: range reduction of scene light to an HDR
display's luminance range (``com.unity.render-pipelines.core/ShaderLibrary/HDROutput.hlsl``,
``HDRMappingFromRec709`` and ``PerformRangeReduction``).

Scene-linear Rec.709 is scaled so that 1.0 is ``paper_white`` cd/m², taken to Rec.2020 and reduced
to ``[min_luminance, peak_luminance]`` by the ITU-R BT.2390 EETF or by Unity's Reinhard curve: on
the intensity ``I`` of ICtCp (hue-preserving, with Unity's desaturation ``(I'/I)²`` of the colour
that got darker), on each channel (hue-shifting), or a blend of both by ``hue_shift``.
"""

from __future__ import annotations

import torch

from .. import color
from ..base.params import Param, scalar_param
from .base import display

__all__ = ["bt2390_eetf", "unity_reinhard_nits", "neutral_hdr", "NEUTRAL_HDR_RANGES", "HDR_PRIMARIES"]

NEUTRAL_HDR_RANGES = {
    "paper_white": (1.0, 10000.0),
    "min_luminance": (0.0, 1.0),
    "peak_luminance": (100.0, 9990.0),  # Unity's Reinhard divides by 10000 - peak
    "hue_shift": (0.0, 1.0),
    "range_reduction": ("bt2390", "reinhard"),
}
"""Luminances in cd/m²; ``hue_shift`` 0 keeps hue, 1 reduces each channel on its own."""

HDR_PRIMARIES = "rec2020"
"""The container of every HDR mode's output: display-linear Rec.2020, 1.0 = ``peak_luminance``."""


def _pq(nits) -> torch.Tensor:
    return color.linear_to_pq(nits, reference=1.0)


def _bt2390_pq(e1: torch.Tensor, min_luminance, peak_luminance) -> torch.Tensor:
    """The EETF on PQ values: ``KS = 1.5 maxLum - 0.5``; above ``KS`` the Hermite spline ``P`` rolls
    off to ``maxLum``; then ``E + minLum (1 - E)⁴`` lifts the black."""
    max_lum, min_lum = _pq(torch.as_tensor(peak_luminance).to(e1)), _pq(torch.as_tensor(min_luminance).to(e1))
    knee = 1.5 * max_lum - 0.5
    t = (e1.clamp(max=1.0) - knee) / (1.0 - knee)
    t2, t3 = t * t, t * t * t
    spline = (2 * t3 - 3 * t2 + 1) * knee + (t3 - 2 * t2 + t) * (1.0 - knee) + (-2 * t3 + 3 * t2) * max_lum
    e2 = torch.where(e1 < knee, e1, spline)
    return e2 + min_lum * (1.0 - e2) ** 4


def bt2390_eetf(nits: torch.Tensor, min_luminance, peak_luminance) -> torch.Tensor:
    """ITU-R BT.2390-4 §5.4 EETF for a mastering range 0..10000 cd/m², in cd/m² (beyond 10000 counts as 10000).

    Examples:
        >>> [round(v, 2) for v in bt2390_eetf(torch.tensor([10.0, 10000.0], dtype=torch.float64), 0.0, 1000.0).tolist()]
        [10.0, 1000.0]
    """
    return color.pq_to_linear(_bt2390_pq(_pq(nits), min_luminance, peak_luminance), reference=1.0)


def unity_reinhard_nits(nits: torch.Tensor, peak_luminance) -> torch.Tensor:
    """Unity's ``ReinhardTonemap(x, peak)``: ``x m / (x + m)``, ``m = 10000 peak / (10000 - peak)``,
    which maps 10000 cd/m² to the peak.

    Examples:
        >>> round(float(unity_reinhard_nits(torch.tensor(10000.0), 1000.0)), 3)
        1000.0
    """
    m = color.PQ_PEAK * peak_luminance / (color.PQ_PEAK - peak_luminance)
    x = nits.clamp_min(0.0)
    return x * m / (x + m)


def _reduce(nits: torch.Tensor, method: str, min_luminance, peak_luminance) -> torch.Tensor:
    if method == "reinhard":
        return unity_reinhard_nits(nits, peak_luminance)
    return bt2390_eetf(nits, min_luminance, peak_luminance)


def _hue_preserving(nits: torch.Tensor, method: str, min_luminance, peak_luminance) -> torch.Tensor:
    """Unity's ``HuePreservingRangeReduction``: reduce ``I``, then scale CtCp by ``min(1, I'/I)²``."""
    ictcp = color.rec2020_to_ictcp(nits)
    intensity, chroma = ictcp.split((1, 2), dim=-3)
    if method == "reinhard":
        reduced = _pq(unity_reinhard_nits(color.pq_to_linear(intensity, reference=1.0), peak_luminance))
    else:  # in PQ, without a round trip through cd/m²
        reduced = _bt2390_pq(intensity, min_luminance, peak_luminance)
    desaturation = (reduced / intensity.clamp_min(1e-6)).clamp(max=1.0) ** 2
    return color.ictcp_to_rec2020(torch.cat((reduced, chroma * desaturation), dim=-3))


def neutral_hdr(image: torch.Tensor, paper_white: Param = 203.0, min_luminance: Param = 0.005, peak_luminance: Param = 1000.0,
                hue_shift: Param = 0.0, range_reduction: str = "bt2390", clip: bool = True) -> torch.Tensor:
    """Unity's HDR output of the Neutral tone mapper: display-linear Rec.2020, 1.0 = ``peak_luminance``.

    ``paper_white`` defaults to BT.2408's HDR reference white (203 cd/m²). Encode for a Rec.2100
    PQ display with ``torchgrade.color.linear_to_pq(x, reference=peak_luminance)`` or
    :class:`torchgrade.output.layer.Display`. Input policy: each Rec.2020 channel is clamped at 10000
    cd/m² (the end of PQ, which the EETF maps to the peak anyway); negative (out-of-gamut) values
    reach the ICtCp path clamped in LMS, as Unity's ``max(0, lms)``.

    Examples:
        >>> grey = torch.full((1, 3, 1, 1), 1.0, dtype=torch.float64)
        >>> round(float(neutral_hdr(grey, min_luminance=0.0)[0, 1, 0, 0]) * 1000.0, 1)  # below the knee: unchanged
        203.0
        >>> round(float(neutral_hdr(grey)[0, 1, 0, 0]) * 1000.0, 1)  # the EETF lifts black by 0.005 cd/m² at 0
        203.9
    """
    # PQ's decode after the ICtCp round trip amplifies float32 rounding to ~4e-4 of the peak on
    # saturated highlights; float64 keeps it below 1e-6 (and ONNX runs the same casts).
    x = image.double()
    white, low, peak, shift = (scalar_param(v, x, name) for v, name in ((paper_white, "paper_white"), (min_luminance, "min_luminance"),
                                                                        (peak_luminance, "peak_luminance"), (hue_shift, "hue_shift")))
    nits = (color.convert(x, "rec709_to_rec2020") * white).clamp(max=color.PQ_PEAK)  # PQ ends at 10000 cd/m²
    keeping = _hue_preserving(nits, range_reduction, low, peak)
    shifting = _reduce(nits, range_reduction, low, peak)
    return display(torch.lerp(keeping, shifting, shift) / peak, clip).to(image.dtype)
