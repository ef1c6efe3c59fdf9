"""Tone mapping: scene-referred linear Rec.709 in, display-referred linear Rec.709 in [0, 1] out.

Every curve clamps its input to ``[0, limit]`` first: negative (out-of-gamut) values map to black
and, as in the source documents, values above 60 are treated as 60 (beyond it every curve here is
within 1/255 of its asymptote, and half-precision evaluation stays finite). The output is clamped
to [0, 1]; sRGB encoding is a separate step (:func:`torchgrade.color.linear_to_srgb`).
"""

from __future__ import annotations

import torch
from torch import nn

from .color import AP1_LUMINANCE, convert, luminance, safe_sqrt, unity_to_aces
from .core import Param, check_image, check_range, sanitize, scalar_param, working_dtype, to_input_dtype
from .params import ParamModule

TONEMAP_INPUT_LIMIT = 60.0
"""Inputs are clamped to this before tone mapping (Catlike Coding, HDR §3.3: 'a limit of 60')."""


def _limited(image: torch.Tensor, limit=TONEMAP_INPUT_LIMIT) -> torch.Tensor:
    return torch.minimum(image.clamp_min(0.0), torch.as_tensor(limit, dtype=image.dtype, device=image.device))


def _display(image: torch.Tensor) -> torch.Tensor:
    return image.clamp(0.0, 1.0)


def reinhard(image: torch.Tensor) -> torch.Tensor:
    """Per-channel Reinhard: ``c / (1 + c)`` with ``c = clamp(x, 0, 60)`` (Reinhard et al. 2002, eq. 3)."""
    c = _limited(image)
    return _display(c / (1.0 + c))


def reinhard_extended(image: torch.Tensor, white_point: Param = 4.0) -> torch.Tensor:
    """Per-channel Reinhard with a white point ``w``: ``c (1 + c / w²) / (1 + c)`` (Reinhard 2002, eq. 4).

    ``c`` is clamped to ``[0, w]``: the curve reaches 1 at ``c = w`` and the display clips beyond it.
    """
    w = scalar_param(white_point, image, "white_point")
    c = _limited(image, w)
    return _display(c * (1.0 + c / (w * w)) / (1.0 + c))


def reinhard_luminance(image: torch.Tensor, white_point: Param = 4.0) -> torch.Tensor:
    """Extended Reinhard on luminance, colour scaled to the new luminance (004 notes, ``reinhard_extended_luminance``).

    ``L' = L (1 + L / w²) / (1 + L)`` and ``rgb' = rgb · L' / L``; the ratio ``L'/L = (1 + L/w²) / (1 + L)``
    needs no division by ``L``, so black pixels stay finite. ``L`` is clamped at 0.
    """
    w = scalar_param(white_point, image, "white_point")
    lum = luminance(image).clamp_min(0.0)
    ratio = (1.0 + lum / (w * w)) / (1.0 + lum)
    return _display(image * ratio)


def _hable_curve(x: torch.Tensor, a, b, c, d, e, f) -> torch.Tensor:
    """Hable's filmic curve ``t(x) = (x (a x + c b) + d e) / (x (a x + b) + d f) - e / f``."""
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


_NEUTRAL = dict(a=0.2, b=0.29, c=0.24, d=0.272, e=0.02, f=0.3)
_NEUTRAL_WHITE_LEVEL = 5.3


def neutral(image: torch.Tensor) -> torch.Tensor:
    """Unity's Neutral tone mapper (``NeutralTonemap``, Color.hlsl): ``t(x·s)·s`` with ``s = 1 / t(5.3)``.

    ``t`` is Hable's curve with a=0.2, b=0.29, c=0.24, d=0.272, e=0.02, f=0.3; the effective white
    point, where the output reaches 1, is ``5.3 / s ≈ 4.035``.
    """
    white = torch.tensor(_NEUTRAL_WHITE_LEVEL, dtype=image.dtype, device=image.device)
    scale = 1.0 / _hable_curve(white, **_NEUTRAL)
    return _display(_hable_curve(_limited(image) * scale, **_NEUTRAL) * scale)


_UNCHARTED2 = dict(a=0.15, b=0.50, c=0.10, d=0.20, e=0.02, f=0.30)


def hable(image: torch.Tensor, exposure_bias: Param = 2.0, white_point: Param = 11.2) -> torch.Tensor:
    """Uncharted 2 filmic curve: ``t(x · bias) / t(w)`` (Hable 2010, slides 142-143; HDR §3.4).

    Constants A=0.15, B=0.50, C=0.10, D=0.20, E=0.02, F=0.30, exposure bias 2 and white point 11.2.
    """
    bias = scalar_param(exposure_bias, image, "exposure_bias")
    w = scalar_param(white_point, image, "white_point")
    return _display(_hable_curve(_limited(image) * bias, **_UNCHARTED2) / _hable_curve(w, **_UNCHARTED2))


# ACES constants (Unity ACES.hlsl, from the ACES 1.0.3 RRT and ODT).
_RRT_GLOW_GAIN, _RRT_GLOW_MID = 0.05, 0.08
_RRT_RED_SCALE, _RRT_RED_PIVOT, _RRT_RED_HUE, _RRT_RED_WIDTH = 0.82, 0.03, 0.0, 135.0
_RRT_SAT_FACTOR, _ODT_SAT_FACTOR = 0.96, 0.93
_DIM_SURROUND_GAMMA = 0.9811
# Luminance fit of RRT 1.0.3 + ODT RGBmonitor_100nits_dim (Unity AcesTonemap; RMSE 0.0013).
_ACES_FIT = dict(a=2.785085, b=0.107772, c=2.936045, d=0.887122, e=0.806889)


def _rgb_saturation(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_saturation``: ``(max(ma, 1e-4) - max(mi, 1e-4)) / max(ma, 1e-2)``."""
    high = rgb.amax(dim=-3, keepdim=True)
    low = rgb.amin(dim=-3, keepdim=True)
    return (high.clamp_min(1e-4) - low.clamp_min(1e-4)) / high.clamp_min(1e-2)


def _rgb_yc(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_yc``: ``(r + g + b + 1.75 sqrt(b(b-g) + g(g-r) + r(r-b))) / 3``."""
    r, g, b = rgb.split(1, dim=-3)
    chroma = safe_sqrt(b * (b - g) + g * (g - r) + r * (r - b))
    return (r + g + b + 1.75 * chroma) / 3.0


def _rgb_hue_degrees(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``rgb_2_hue`` in [0, 360): ``atan2(sqrt(3)(g - b), 2r - g - b)``; 0 for neutrals."""
    r, g, b = rgb.split(1, dim=-3)
    y = 3.0**0.5 * (g - b)
    x = 2.0 * r - g - b
    neutral_pixel = (x == 0) & (y == 0)
    hue = torch.rad2deg(torch.atan2(y, torch.where(neutral_pixel, torch.ones_like(x), x)))
    hue = torch.where(neutral_pixel, torch.zeros_like(hue), hue)
    return torch.where(hue < 0, hue + 360.0, hue)


def _sigmoid_shaper(x: torch.Tensor) -> torch.Tensor:
    """ACES ``sigmoid_shaper``: a 0..1 sigmoid spanning -2..2."""
    t = (1.0 - torch.abs(x / 2.0)).clamp_min(0.0)
    return (1.0 + torch.sign(x) * (1.0 - t * t)) / 2.0


def _glow(yc: torch.Tensor, gain: torch.Tensor, mid: float) -> torch.Tensor:
    """ACES ``glow_fwd``: full gain below 2/3·mid, none above 2·mid, ``gain (mid / yc - 1/2)`` between."""
    between = gain * (mid / yc.clamp_min(2.0 / 3.0 * mid) - 0.5)
    return torch.where(yc <= 2.0 / 3.0 * mid, gain, torch.where(yc >= 2.0 * mid, torch.zeros_like(gain), between))


def _smoothstep(edge0, edge1, x: torch.Tensor) -> torch.Tensor:
    t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _lerp_to_luminance(rgb: torch.Tensor, factor: float) -> torch.Tensor:
    """``lerp(Y, rgb, factor)`` with AP1 luminance (the RRT/ODT desaturation)."""
    y = luminance(rgb, "ap1")
    return y + factor * (rgb - y)


def _dark_to_dim_surround(rgb: torch.Tensor) -> torch.Tensor:
    """ACES ``darkSurround_to_dimSurround``: ``Y → Y^0.9811`` in xyY, chromaticity kept."""
    xyz = convert(rgb, "ap1_to_xyz")
    big_x, big_y, big_z = xyz.split(1, dim=-3)
    total = (big_x + big_y + big_z).clamp_min(1e-4)
    x, y = big_x / total, big_y / total
    new_y = big_y.clamp(0.0, 65504.0)
    new_y = torch.where(new_y > 0, torch.where(new_y > 0, new_y, torch.ones_like(new_y)) ** _DIM_SURROUND_GAMMA, new_y)
    m = new_y / y.clamp_min(1e-4)
    xyz = torch.cat((x * m, new_y, (1.0 - x - y) * m), dim=-3)
    return convert(xyz, "xyz_to_ap1")


def aces_fitted(aces: torch.Tensor) -> torch.Tensor:
    """Unity ``AcesTonemap`` on ACES2065-1 input: RRT glow and red modifier, desaturation, the luminance
    fit ``x (a x + b) / (x (c x + d) + e)`` of RRT+ODT (RGB monitor, 100 nits, dim), dim surround,
    ODT desaturation, then AP1 → XYZ → D60→D65 → Rec.709."""
    saturation = _rgb_saturation(aces)
    s = _sigmoid_shaper((saturation - 0.4) / 0.2)
    aces = aces * (1.0 + _glow(_rgb_yc(aces), _RRT_GLOW_GAIN * s, _RRT_GLOW_MID))

    centered = _rgb_hue_degrees(aces) - _RRT_RED_HUE
    centered = torch.where(centered < -180.0, centered + 360.0, torch.where(centered > 180.0, centered - 360.0, centered))
    hue_weight = _smoothstep(0.0, 1.0, 1.0 - torch.abs(2.0 * centered / _RRT_RED_WIDTH)) ** 2
    red, green_blue = aces.split((1, 2), dim=-3)
    red = red + hue_weight * saturation * (_RRT_RED_PIVOT - red) * (1.0 - _RRT_RED_SCALE)
    aces = torch.cat((red, green_blue), dim=-3)

    acescg = _lerp_to_luminance(convert(aces, "ap0_to_ap1").clamp_min(0.0), _RRT_SAT_FACTOR)
    k = _ACES_FIT
    fitted = acescg * (k["a"] * acescg + k["b"]) / (acescg * (k["c"] * acescg + k["d"]) + k["e"])
    linear = _lerp_to_luminance(_dark_to_dim_surround(fitted), _ODT_SAT_FACTOR)
    return convert(convert(convert(linear, "ap1_to_xyz"), "d60_to_d65"), "xyz_to_rec709")


def aces(image: torch.Tensor) -> torch.Tensor:
    """ACES filmic tone mapping as Unity does it: ``AcesTonemap(unity_to_ACES(min(x, 60)))`` (HDR §3.5)."""
    return _display(aces_fitted(unity_to_aces(_limited(image))))


def no_tonemap(image: torch.Tensor) -> torch.Tensor:
    """No curve: the display simply clips to [0, 1]."""
    return _display(image)


_CURVES = {
    "none": (no_tonemap, ()),
    "reinhard": (reinhard, ()),
    "reinhard_extended": (reinhard_extended, ("white_point",)),
    "reinhard_luminance": (reinhard_luminance, ("white_point",)),
    "neutral": (neutral, ()),
    "aces": (aces, ()),
    "hable": (hable, ("exposure_bias", "white_point")),
}
TONEMAP_MODES = tuple(_CURVES)
"""Every ``ToneMap`` mode."""

_DEFAULT_WHITE_POINT = 4.0
_HABLE_WHITE_POINT = 11.2
_DEFAULT_EXPOSURE_BIAS = 2.0


def tonemap(image: torch.Tensor, mode: str = "neutral", **params: Param) -> torch.Tensor:
    """Apply tone mapper ``mode`` (one of :data:`TONEMAP_MODES`) with its parameters.

    The input passes the library's non-finite policy first; float16/bfloat16 inputs are computed in
    float32 and returned in their own dtype.
    """
    check_image(image)
    curve, names = _curve(mode)
    unknown = set(params) - set(names)
    if unknown:
        raise ValueError(f"tone mapper {mode!r} takes {list(names) or 'no parameters'}, got {sorted(unknown)}")
    working = sanitize(working_dtype(image))
    return to_input_dtype(curve(working, **params), image)


def _curve(mode: str):
    if mode not in _CURVES:
        raise ValueError(f"unknown tone mapping mode {mode!r}; choose one of {', '.join(TONEMAP_MODES)}")
    return _CURVES[mode]


class ToneMap(ParamModule):
    """Tone mapping layer: ``ToneMap(mode="neutral")``; see :data:`TONEMAP_MODES`.

    ``white_point`` (``reinhard_extended``, ``reinhard_luminance``: default 4; ``hable``: 11.2) and
    ``exposure_bias`` (``hable``: 2) accept numbers, 0-d or per-sample ``(B,)`` tensors, or
    ``nn.Parameter`` to learn them.
    """

    def __init__(self, mode: str = "neutral", white_point: Param | None = None, exposure_bias: Param | None = None):
        super().__init__()
        _, names = _curve(mode)
        self.mode = mode
        given = {"white_point": white_point, "exposure_bias": exposure_bias}
        for name, value in given.items():
            if value is not None and name not in names:
                raise ValueError(f"tone mapper {mode!r} takes no {name!r}")
        if "white_point" in names:
            white_point = (_HABLE_WHITE_POINT if mode == "hable" else _DEFAULT_WHITE_POINT) if white_point is None else white_point
            check_range(white_point, "white_point", 1e-3, 1e4)
            self.set_param("white_point", white_point)
        if "exposure_bias" in names:
            exposure_bias = _DEFAULT_EXPOSURE_BIAS if exposure_bias is None else exposure_bias
            check_range(exposure_bias, "exposure_bias", 1e-3, 1e3)
            self.set_param("exposure_bias", exposure_bias)

    @property
    def is_identity(self) -> bool:
        """Tone mapping is never skipped: even ``"none"`` clips to the display range."""
        return False

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return tonemap(image, self.mode, **self.params())

    def extra_repr(self) -> str:
        return f"mode={self.mode!r}" + "".join(f", {k}={v}" for k, v in self.config().items() if k != "mode")

    def config(self) -> dict:
        """The constructor arguments as plain values."""
        return {"mode": self.mode, **self.plain_params()}
