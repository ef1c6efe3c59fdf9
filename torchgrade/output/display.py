"""``Display``: the last stage of a look, encoding display-linear light for a display: sRGB, BT.1886,
SMPTE ST 2084 (PQ) or BT.2100 HLG, in Rec.709 or Rec.2020 primaries, or display-linear for EXR.

A tone mapper returns display-linear values with 1.0 = the display's white: SDR white (100 cd/m²)
for the SDR modes, ``peak_luminance`` for the HDR modes (:data:`torchgrade.tonemap.HDR_MODES`,
whose output is Rec.2020). ``Display`` takes that, changes primaries if asked and encodes; the
maths is traceable, so an exported look carries it.
"""

from __future__ import annotations

import torch

from .. import color
from ..base.images import check_image
from ..base.params import Param, is_plain_number, scalar_param
from ..tonemap import HDR_MODES

__all__ = ["encode_display", "display_settings", "DISPLAY_ENCODINGS", "DISPLAY_PRIMARIES", "DISPLAY_PRESETS",
           "HLG_PEAK_RANGE", "HLG_BLACK", "hlg_inverse_eotf"]

DISPLAY_ENCODINGS = ("srgb", "bt1886", "pq", "hlg", "linear")
DISPLAY_PRIMARIES = ("rec709", "rec2020")
_LUMINANCE_ROWS = {"rec709": (0.2126, 0.7152, 0.0722), "rec2020": (0.2627, 0.6780, 0.0593)}
"""Luminance weights of each container (ITU-R BT.709 and BT.2100), for HLG's OOTF."""

HLG_PEAK_RANGE = (100.0, 10000.0)
"""Nominal peaks (cd/m²) an HLG display may have here. BT.2100's system gamma ``1.2 + 0.42 log10(Lw / 1000)`` falls
to 0.78 at 100 cd/m² and to 0 near 1.4 cd/m², where undoing the OOTF (a power ``(1 - γ) / γ``) diverges: at 1 cd/m²
every pixel came out 1.0, at 1.4 black."""

HLG_BLACK = 1e-10
"""Display luminance (over the peak) below which undoing the OOTF takes the luminance as this: the power
``(1 - γ) / γ`` of a luminance near 0 has an infinite slope (a gradient of -inf at 1e-45 before); below it every
signal is under 1e-5 of a code."""


DISPLAY_PRESETS = {
    "sdr": {"encoding": "srgb"},
    "bt1886": {"encoding": "bt1886"},
    "hdr_pq": {"encoding": "pq", "primaries": "rec2020"},
    "hdr_hlg": {"encoding": "hlg", "primaries": "rec2020"},
    "linear": {"encoding": "linear"},
    "linear_rec2020": {"encoding": "linear", "primaries": "rec2020"},
}
"""Display targets by name: sRGB monitor, BT.1886 video, Rec.2100 PQ and HLG, display-linear (for EXR)."""


def display_settings(spec, tonemap=None) -> dict:
    """``Display`` arguments from a preset name (:data:`DISPLAY_PRESETS`) or a dict, completed with an
    HDR tone mapper's ``peak_luminance`` and output primaries unless given.

    Examples:
        >>> from torchgrade import ToneMap
        >>> display_settings("hdr_pq", ToneMap("neutral_hdr", peak_luminance=600.0))
        {'peak_luminance': 600.0, 'input_primaries': 'rec2020', 'encoding': 'pq', 'primaries': 'rec2020'}
    """
    if isinstance(spec, str):
        if spec not in DISPLAY_PRESETS:
            raise ValueError(f"display must be one of {tuple(DISPLAY_PRESETS)} or a dict of Display's arguments, got {spec!r}")
        spec = DISPLAY_PRESETS[spec]
    if not isinstance(spec, dict) or getattr(tonemap, "mode", None) not in HDR_MODES:
        return spec
    return {"peak_luminance": float(tonemap.peak_luminance), "input_primaries": HDR_MODES[tonemap.mode], **spec}


def hlg_inverse_eotf(display_linear: torch.Tensor, peak_luminance: Param = 1000.0, weights=_LUMINANCE_ROWS["rec2020"]) -> torch.Tensor:
    """BT.2100 HLG signal of display light (1.0 = ``peak_luminance`` = the HLG display's nominal peak, black 0).

    Undoes the OOTF ``F = Lw Ys^(γ-1) E`` with ``γ = 1.2 + 0.42 log10(Lw / 1000)``: ``E = F Yd^((1-γ)/γ)``
    (``Yd`` the display luminance over ``Lw``, at least :data:`HLG_BLACK`), then applies the HLG OETF. ``Lw`` is
    taken within :data:`HLG_PEAK_RANGE` (the stage and :func:`encode_display` refuse a peak outside it; a learnable one
    is held inside).

    Examples:
        >>> round(float(hlg_inverse_eotf(torch.ones(3, 1, 1))[0, 0, 0]), 4)  # peak white: code 1
        1.0
    """
    peak = torch.as_tensor(peak_luminance, dtype=display_linear.dtype, device=display_linear.device)
    gamma = 1.2 + 0.42 * torch.log10(peak.clamp(*HLG_PEAK_RANGE) / 1000.0)
    light = display_linear.clamp_min(0.0)
    y = sum(w * c for w, c in zip(weights, light.split(1, dim=-3)))
    scene = light * y.clamp_min(HLG_BLACK) ** ((1.0 - gamma) / gamma)
    return color.hlg_oetf(scene.clamp(max=1.0))


def encode_display(image: torch.Tensor, encoding: str = "srgb", primaries: str = "rec709", peak_luminance: Param = 100.0,
                   input_primaries: str = "rec709") -> torch.Tensor:
    """Display-linear ``(..., 3, H, W)`` in ``input_primaries`` (1.0 = ``peak_luminance`` cd/m²) → ``encoding`` in ``primaries``.

    Values are clipped to the display range [0, 1] first (the container's gamut and peak); ``"pq"``
    encodes ``x * peak_luminance`` cd/m², ``"hlg"`` treats ``peak_luminance`` as the display's nominal
    peak (within :data:`HLG_PEAK_RANGE`), ``"bt1886"`` is ``x^(1/2.4)`` (black 0), ``"linear"`` returns the clipped
    display light.

    Examples:
        >>> white = torch.ones(1, 3, 1, 1)
        >>> round(float(encode_display(white, "pq", "rec2020", 1000.0)[0, 0, 0, 0]), 4)  # 1000 cd/m²
        0.7518
        >>> round(float(encode_display(0.18 * white, "srgb")[0, 0, 0, 0]), 4)
        0.4614
    """
    check_image(image)
    if encoding == "hlg" and is_plain_number(peak_luminance) and not HLG_PEAK_RANGE[0] <= peak_luminance <= HLG_PEAK_RANGE[1]:
        # a number compared in Python (no tensor a frame); a tensor is checked by the stage, and held in range
        raise ValueError(f"an HLG display's peak_luminance must lie in [{HLG_PEAK_RANGE[0]}, {HLG_PEAK_RANGE[1]}], "
                         f"got {peak_luminance}")
    if primaries != input_primaries:
        image = color.convert(image, f"{input_primaries}_to_{primaries}")
    linear = image.clamp(0.0, 1.0)
    peak = scalar_param(peak_luminance, linear, "peak_luminance")
    if encoding == "srgb":
        return color.linear_to_srgb(linear)
    if encoding == "bt1886":
        return color.safe_pow(linear, 1.0 / 2.4)
    if encoding == "pq":
        return color.linear_to_pq(linear, reference=peak)
    if encoding == "hlg":
        return hlg_inverse_eotf(linear, peak, _LUMINANCE_ROWS[primaries])
    return linear
