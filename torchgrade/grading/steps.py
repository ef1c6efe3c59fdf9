"""The steps of Unity's colour grade, one pure, differentiable function each.

Each function takes and returns ``(..., 3, H, W)`` tensors; controls broadcast as the library's
conventions say (numbers, 0-d, per-sample). :func:`torchgrade.grading.grade.color_grade` chains them in
Unity's order and skips the steps left at identity; see :mod:`torchgrade.grading.grade` for the order,
units and sources. Contrast (:mod:`torchgrade.grading.contrast`) and split toning (:mod:`torchgrade.grading.toning`)
have modules of their own; their steps are named here too.
"""

from __future__ import annotations

import torch

from ..base.images import HALF_MAX, NEGLIGIBLE_LIGHT
from ..base.params import Param, color_param, matrix_param, scalar_param
from ..base.planes import (
    apply_matrix,
    bounded_pow,
    channel_max,
    each_plane,
    like_image,
    matrix_on,
    matrix_product,
    per_channel,
)
from ..color import (
    AP1_LUMINANCE,
    CHANNEL,
    REC709_LUMINANCE,
    hsv_planes,
    luminance,
    rgb_from_hsv_planes,
    rgb_planes_from_hsv,
    srgb_to_linear,
)
from ..color.spaces import shared_matrix
from ..runtime import constant, where
from .contrast import contrast, contrast_space, log_contrast
from .curves import evaluate_curve
from .toning import soft_light, split_toning

__all__ = [
    "IDENTITY_MATRIX",
    "IDENTITY_TRACKBALL",
    "post_exposure",
    "white_balance_coefficients",
    "white_balance_matrix",
    "white_balance",
    "contrast_space",
    "log_contrast",
    "contrast",
    "color_filter",
    "soft_light",
    "split_toning",
    "channel_mixer",
    "smoothstep",
    "shadows_midtones_highlights",
    "lift_gamma_gain_coefficients",
    "lift_gamma_gain",
    "hue_shift",
    "saturation_curves",
    "saturation",
    "saturation_matrix",
    "fast_tonemap",
    "fast_tonemap_inverse",
    "yrgb_curves",
]

IDENTITY_MATRIX = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
IDENTITY_TRACKBALL = (1.0, 1.0, 1.0, 0.0)
"""A lift, gamma or gain trackball that changes nothing: white, offset 0."""


def _channels(t: torch.Tensor) -> torch.Tensor:
    """A scalar parameter (0-d or (B,1,1,1)) as a single-channel map that can be concatenated to RGB."""
    return t.reshape(t.shape[:1] + (1, 1, 1)) if t.dim() else t.reshape(1, 1, 1)


def post_exposure(image: torch.Tensor, stops: Param) -> torch.Tensor:
    """Post exposure: ``rgb · 2^stops``.

    Examples:
        >>> post_exposure(torch.full((3, 1, 1), 0.25), 2.0).flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    return image * torch.exp2(scalar_param(stops, image, "post_exposure"))


def white_balance_coefficients(temperature: torch.Tensor, tint: torch.Tensor) -> torch.Tensor:
    """LMS gains of Unity's ``ColorUtils.ColorBalanceToLMSCoeffs(temperature, tint)``.

    ``x = 0.31271 - t1·(0.1 if t1 < 0 else 0.05)``, ``y = 2.87x - 3x² - 0.27509508 + t2·0.05`` with
    ``t1 = temperature/65``, ``t2 = tint/65``; the white ``(x, y)`` goes to CAT02 LMS and the gains are
    D65's LMS ``(0.949237, 1.03542, 1.08728)`` divided by it. Returns ``(..., 3, 1, 1)``.

    Examples:
        >>> gains = white_balance_coefficients(torch.tensor(0.0), torch.tensor(0.0))
        >>> bool(torch.allclose(gains, torch.ones(3, 1, 1), atol=1e-5))
        True
    """
    t1, t2 = _channels(temperature) / 65.0, _channels(tint) / 65.0
    x = 0.31271 - torch.where(t1 < 0, t1 * 0.1, t1 * 0.05)
    y = 2.87 * x - 3.0 * x * x - 0.27509508 + t2 * 0.05
    big_x, big_z = x / y, (1.0 - x - y) / y
    lms = torch.cat(
        (
            0.7328 * big_x + 0.4296 - 0.1624 * big_z,
            -0.7036 * big_x + 1.6975 + 0.0061 * big_z,
            0.0030 * big_x + 0.0136 + 0.9834 * big_z,
        ),
        dim=-3,
    )
    d65 = constant((0.949237, 1.03542, 1.08728), lms).reshape(3, 1, 1)
    return d65 / lms


def white_balance_matrix(image: torch.Tensor, temperature: Param = 0.0, tint: Param = 0.0) -> torch.Tensor:
    """White balance as one matrix on linear Rec.709: ``LMSToLinear · diag(gains) · LinearToLMS`` with the
    gains of :func:`white_balance_coefficients`; ``(3, 3)``, or ``(B, 3, 3)`` for per-sample controls.

    Examples:
        >>> m = white_balance_matrix(torch.zeros(1, 3, 1, 1), temperature=0.0)
        >>> bool(torch.allclose(m, torch.eye(3), atol=1e-4))
        True
    """
    gains = white_balance_coefficients(scalar_param(temperature, image, "temperature"), scalar_param(tint, image, "tint"))
    return matrix_product(shared_matrix("lms_to_linear", image), gains[..., 0] * shared_matrix("linear_to_lms", image))


def white_balance(image: torch.Tensor, temperature: Param = 0.0, tint: Param = 0.0) -> torch.Tensor:
    """White balance: scale in LMS by :func:`white_balance_coefficients` (Unity ``ColorGradeWhiteBalance``),
    applied as :func:`white_balance_matrix`.

    Examples:
        >>> warm = white_balance(torch.full((3, 1, 1), 0.5), temperature=50.0).flatten()
        >>> bool(warm[0] > warm[2])
        True
    """
    return apply_matrix(white_balance_matrix(image, temperature, tint), image)


def color_filter(image: torch.Tensor, color) -> torch.Tensor:
    """Colour filter: multiply by the colour, given sRGB-encoded as in Unity's picker (HDR allowed).

    Examples:
        >>> color_filter(torch.ones(3, 1, 1), (1.0, 1.0, 0.0)).flatten().tolist()
        [1.0, 1.0, 0.0]
    """
    return image * srgb_to_linear(color_param(color, image, "color_filter"))


def channel_mixer(image: torch.Tensor, mixer=IDENTITY_MATRIX) -> torch.Tensor:
    """Channel mixer: ``rgb' = M · rgb``, rows are the output channels (1.0 = Unity's 100%). An image given as its three
    planes (a tuple, :func:`~torchgrade.runtime.strips.pixelwise`) is returned as planes.

    Examples:
        >>> swap = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        >>> channel_mixer(torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1), swap).flatten().tolist()
        [2.0, 1.0, 3.0]
    """
    return matrix_on(matrix_param(mixer, like_image(image), "channel_mixer"), image)


def smoothstep(edge0, edge1, x: torch.Tensor) -> torch.Tensor:
    """HLSL ``smoothstep``: ``t²(3 - 2t)`` with ``t = saturate((x - edge0) / (edge1 - edge0))``.

    Examples:
        >>> smoothstep(0.0, 1.0, torch.tensor([-1.0, 0.5, 2.0])).tolist()
        [0.0, 0.5, 1.0]
    """
    t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def shadows_midtones_highlights(
    image: torch.Tensor,
    shadows=(1.0, 1.0, 1.0),
    midtones=(1.0, 1.0, 1.0),
    highlights=(1.0, 1.0, 1.0),
    shadows_start: Param = 0.0,
    shadows_end: Param = 0.3,
    highlights_start: Param = 0.55,
    highlights_end: Param = 1.0,
    luminance_weights="rec709",
) -> torch.Tensor:
    """Zone tints (Unity ``ColorGradingShadowsMidtonesHighlights``), colours sRGB-encoded as in Unity.

    ``ws = 1 - smoothstep(s0, s1, Y)``, ``wh = smoothstep(h0, h1, Y)``, ``wm = 1 - ws - wh``;
    ``rgb' = rgb · (S ws + M wm + H wh)``. An image given as its three planes (a tuple,
    :func:`~torchgrade.runtime.strips.pixelwise`) is returned as planes.

    Examples:
        >>> image = torch.rand(3, 2, 2)
        >>> bool(torch.equal(shadows_midtones_highlights(image), image))  # white tints change nothing
        True
    """
    lum = luminance(image, luminance_weights)
    shadow_weight = 1.0 - smoothstep(
        scalar_param(shadows_start, lum, "shadows_start"), scalar_param(shadows_end, lum, "shadows_end"), lum
    )
    highlight_weight = smoothstep(
        scalar_param(highlights_start, lum, "highlights_start"), scalar_param(highlights_end, lum, "highlights_end"), lum
    )
    midtone_weight = 1.0 - shadow_weight - highlight_weight
    tints = (srgb_to_linear(color_param(color, lum, name)) for color, name in zip((shadows, midtones, highlights), ("shadows", "midtones", "highlights")))
    return per_channel(lambda x, s, m, h: x * (s * shadow_weight + m * midtone_weight + h * highlight_weight), image, *tints)


def _trackball(value, image: torch.Tensor, name: str) -> tuple:
    """A trackball ``(r, g, b, w)``, or per sample ``(B, 4)``, as its colour and its offset ``w``."""
    t = value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=image.dtype, device=image.device)
    if t.dim() not in (1, 2) or t.shape[-1] != 4:
        raise ValueError(f"parameter {name!r} must be a trackball (r, g, b, w) or per-sample (B, 4), got shape {tuple(t.shape)}")
    return color_param(t[..., :3], image, name), scalar_param(t[..., 3], image, name)


def _minus_luminance(rgb: torch.Tensor) -> torch.Tensor:
    """``rgb - Y(rgb)`` for colours ``(..., 3, 1, 1)``, as ``sum_j w_j (rgb_i - rgb_j)`` with the Rec.709
    weights normalised to sum 1 (Unity's sum to 1.0000001), so a grey colour gives exactly 0."""
    weights = constant(REC709_LUMINANCE, rgb)
    weights = (weights / weights.sum()).reshape(3, 1, 1)
    return ((rgb.unsqueeze(-3) - rgb.unsqueeze(-4)) * weights).sum(dim=-3)


def _balanced(value, image: torch.Tensor, name: str, scale: float) -> tuple:
    """A trackball's colour decoded and scaled, minus its luminance (so it leaves luminance alone), and its ``w``."""
    rgb, offset = _trackball(value, image, name)
    return _minus_luminance(srgb_to_linear(rgb) * scale), offset


def lift_gamma_gain_coefficients(lift, gamma, gain, image: torch.Tensor) -> tuple:
    """Unity ``ColorUtils.PrepareLiftGammaGain``: ``(lift, 1 / gamma, gain)`` as ``(..., 3, 1, 1)``.

    With ``dec`` the sRGB decode and ``Y`` Rec.709 luminance, for each trackball ``(rgb, w)``:
    ``lift = l - Y(l) + w`` with ``l = dec(rgb) · 0.15``; ``1 / max(g - Y(g) + w + 1, 1e-3)`` with
    ``g = dec(rgb) · 0.8``; ``gain = k - Y(k) + w + 1`` with ``k = dec(rgb) · 0.8``. ``Y`` uses
    weights summing to exactly 1 (see :func:`_minus_luminance`), so identity trackballs give exactly
    ``(0, 1, 1)`` where Unity's are off by 1e-7.

    Examples:
        >>> lift, inverse_gamma, gain = lift_gamma_gain_coefficients(IDENTITY_TRACKBALL, IDENTITY_TRACKBALL, IDENTITY_TRACKBALL, torch.ones(3, 1, 1))
        >>> lift.flatten().tolist(), inverse_gamma.flatten().tolist(), gain.flatten().tolist()
        ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0])
    """
    lift_rgb, lift_offset = _balanced(lift, image, "lift", 0.15)
    gamma_rgb, gamma_offset = _balanced(gamma, image, "gamma", 0.8)
    gain_rgb, gain_offset = _balanced(gain, image, "gain", 0.8)
    inverse_gamma = 1.0 / (gamma_rgb + gamma_offset + 1.0).clamp_min(1e-3)
    return lift_rgb + lift_offset, inverse_gamma, gain_rgb + gain_offset + 1.0


def lift_gamma_gain(image: torch.Tensor, lift=IDENTITY_TRACKBALL, gamma=IDENTITY_TRACKBALL, gain=IDENTITY_TRACKBALL) -> torch.Tensor:
    """Lift, gamma, gain (Unity ``LiftGammaGainHDR``): ``c = rgb · gain + lift``, ``sign(c) |c|^(1/gamma)``.

    The trackballs are prepared by :func:`lift_gamma_gain_coefficients`; the power is mirrored for
    negative values (ACEScg can be negative) and saturates at ±65504 (:func:`~torchgrade.base.planes.bounded_pow`):
    Unity's own minimum gamma is a power of 1000, which overflows float32 from 1.1 up.

    An image given as its three planes (a tuple, :func:`~torchgrade.runtime.strips.pixelwise`) is returned
    as planes.

    Examples:
        >>> lift_gamma_gain(torch.full((3, 1, 1), 0.5), gain=(1.0, 1.0, 1.0, 1.0)).flatten().tolist()  # offset 1: double
        [1.0, 1.0, 1.0]
    """
    return per_channel(_lift_gamma_gain_of, image, *lift_gamma_gain_coefficients(lift, gamma, gain, like_image(image)))


def _lift_gamma_gain_of(x: torch.Tensor, lift: torch.Tensor, inverse_gamma: torch.Tensor, gain: torch.Tensor) -> torch.Tensor:
    """``sign(c) |c|^(1/gamma)`` of ``c = x · gain + lift``, for coefficients that broadcast against ``x``."""
    c = x * gain + lift
    return torch.sign(c) * bounded_pow(c.abs(), inverse_gamma)


def _hsv(image: torch.Tensor) -> tuple:
    """:func:`~torchgrade.color.hsv_planes` of ``image`` (or of its three planes, a tuple), negligible light taken as black."""
    # Hue divides by the chroma (max - min): ACEScg turns a grey 1e-38 into a tinted one, whose hue's gradient overflows.
    lit = channel_max(image) > NEGLIGIBLE_LIGHT
    return hsv_planes(each_plane(lambda plane: where(lit, plane, 0.0), image))


def hue_shift(image: torch.Tensor, degrees: Param, hue_vs_hue=None) -> torch.Tensor:
    """Hue shift in HSV, wrapping around the colour wheel (Unity ``ColorGradingHueShift``); RGB ≥ 0.

    With a ``hue_vs_hue`` curve the shifted hue ``h`` moves on by ``curve(h) - 0.5`` turns (URP ``LutBuilderHdr``).
    An image given as its three planes (a tuple, :func:`~torchgrade.runtime.strips.pixelwise`) is returned
    as planes.

    Examples:
        >>> red = torch.tensor([1.0, 0.0, 0.0]).reshape(3, 1, 1)
        >>> [round(v, 4) for v in hue_shift(red, 120.0).flatten().tolist()]
        [0.0, 1.0, 0.0]
    """
    hue, sat, value = _hsv(image)
    hue = torch.remainder(hue + scalar_param(degrees, hue, "hue_shift") / 360.0, 1.0)
    if hue_vs_hue is not None:
        hue = torch.remainder(hue + evaluate_curve(hue_vs_hue, hue, periodic=True, name="hue_vs_hue") - 0.5, 1.0)
    return (rgb_planes_from_hsv if isinstance(image, tuple) else rgb_from_hsv_planes)(hue, sat, value)


def saturation_curves(image: torch.Tensor, hue_vs_sat=None, sat_vs_sat=None, lum_vs_sat=None, luminance_weights="rec709") -> torch.Tensor:
    """The saturation factor of the curves (URP ``LutBuilderHdr``), ``(..., 1, H, W)``; RGB ≥ 0, an image or its three
    planes (a tuple, :func:`~torchgrade.runtime.strips.pixelwise`).

    ``2 HueVsSat(h) · 2 SatVsSat(s) · 2 LumVsSat(Y)`` of the pixel's HSV hue, HSV saturation and
    luminance; curves not given count as 1.

    Examples:
        >>> flat = ((0.0, 0.5), (0.5, 0.5))
        >>> saturation_curves(torch.rand(3, 2, 2), hue_vs_sat=flat).unique().tolist()
        [1.0]
    """
    hue, sat, _ = _hsv(image)
    axes = {"hue_vs_sat": (hue_vs_sat, hue, True), "sat_vs_sat": (sat_vs_sat, sat, False)}
    if lum_vs_sat is not None:
        axes["lum_vs_sat"] = (lum_vs_sat, luminance(image, luminance_weights), False)
    factor = torch.ones_like(hue)
    for name, (points, value, periodic) in axes.items():
        if points is not None:
            factor = factor * (2.0 * evaluate_curve(points, value, periodic, name))
    return factor


def saturation(image: torch.Tensor, amount: Param, luminance_weights="rec709", factor=None) -> torch.Tensor:
    """Saturation about luminance: ``Y + (rgb - Y)(1 + amount/100)``; -100 gives grey ``Y``.

    ``factor`` (from :func:`saturation_curves`) multiplies ``1 + amount/100``, as URP does. An image given as its three
    planes (a tuple, :func:`~torchgrade.runtime.strips.pixelwise`) is returned as planes.

    Examples:
        >>> grey = saturation(torch.tensor([1.0, 0.0, 0.0]).reshape(3, 1, 1), -100.0).flatten()
        >>> bool(grey[0] == grey[1] == grey[2])
        True
    """
    lum = luminance(image, luminance_weights)
    scale = 1.0 + scalar_param(amount, lum, "saturation") * 0.01
    scale = scale if factor is None else scale * factor
    return each_plane(lambda plane: lum + (plane - lum) * scale, image)


def saturation_matrix(image: torch.Tensor, amount: Param, luminance_weights="rec709") -> torch.Tensor:
    """:func:`saturation` without curves as one matrix: ``s I + (1 - s) 1 wᵀ``, ``s = 1 + amount/100`` and ``w`` the
    luminance weights; ``(3, 3)``, or ``(B, 3, 3)`` for a per-sample amount.

    Examples:
        >>> image = torch.rand(1, 3, 2, 2)
        >>> bool(torch.allclose(apply_matrix(saturation_matrix(image, 30.0), image), saturation(image, 30.0), atol=1e-6))
        True
    """
    scale = 1.0 + scalar_param(amount, image, "saturation") * 0.01
    scale = scale.reshape(scale.shape[:1] + (1, 1)) if scale.dim() else scale
    luminance = {"rec709": REC709_LUMINANCE, "ap1": AP1_LUMINANCE}[luminance_weights]
    weights = constant(luminance, image).expand(3, 3)
    return scale * torch.eye(3, dtype=image.dtype, device=image.device) + (1.0 - scale) * weights


def fast_tonemap(image: torch.Tensor) -> torch.Tensor:
    """Unity ``FastTonemap``: ``c / (1 + max(r, g, b))`` (the max taken ≥ 0), HDR into [0, 1).

    Examples:
        >>> fast_tonemap(torch.tensor([3.0, 1.0, 0.0]).reshape(3, 1, 1)).flatten().tolist()
        [0.75, 0.25, 0.0]
    """
    return image / (1.0 + channel_max(image).clamp_min(0.0))


def fast_tonemap_inverse(image: torch.Tensor) -> torch.Tensor:
    """Unity ``FastTonemapInvert``: ``c / (1 - max(r, g, b))``, the divisor kept ≥ 1/65505 (outputs ≤ 65505).

    Examples:
        >>> fast_tonemap_inverse(torch.tensor([0.75, 0.25, 0.0]).reshape(3, 1, 1)).flatten().tolist()
        [3.0, 1.0, 0.0]
    """
    return image / (1.0 - channel_max(image)).clamp_min(1.0 / (1.0 + HALF_MAX))


def yrgb_curves(image: torch.Tensor, master=None, red=None, green=None, blue=None) -> torch.Tensor:
    """Master, then red/green/blue curves in FastTonemap space, then ``max(0)`` (URP ``LutBuilderHdr``).

    The master curve maps each channel; each colour curve its own. Curves not given leave values alone.

    Examples:
        >>> image = torch.rand(3, 2, 2)
        >>> bool(torch.allclose(yrgb_curves(image, master=((0.0, 0.0), (1.0, 1.0))), image, atol=1e-6))
        True
    """
    x = fast_tonemap(image)
    if master is not None:
        x = evaluate_curve(master, x, name="curve_master")
    curves = {"curve_red": red, "curve_green": green, "curve_blue": blue}
    channels = [c if p is None else evaluate_curve(p, c, name=n) for c, (n, p) in zip(x.split(1, dim=CHANNEL), curves.items())]
    return fast_tonemap_inverse(torch.cat(channels, dim=CHANNEL)).clamp_min(0.0)
