"""Colour grading in Unity URP/HDRP's order, with Unity's controls and units.

Order (Catlike Coding, Color Grading §1-2, matching Unity's ``ColorGrade``; the lift/gamma/gain
and curve steps where URP's LUT builder ``LutBuilderHdr`` puts them)::

    post exposure -> white balance -> contrast (LogC, or ACEScc) -> colour filter -> max(0)
    -> split toning -> channel mixer -> max(0) -> shadows/midtones/highlights
    -> lift/gamma/gain -> max(0) -> hue shift and hue-vs-hue -> saturation (scaled by the
    hue-vs-sat, sat-vs-sat and lum-vs-sat curves of the colour before the hue shift)
    -> master/red/green/blue curves (in FastTonemap space) -> max(0)

Units follow Unity's inspector so a look made there can be typed in: post exposure in stops;
temperature, tint, contrast, saturation and split balance in -100..100; hue shift in degrees.
Colours are given as Unity's colour pickers show them (sRGB-encoded): the colour filter and the
shadows/midtones/highlights colours are decoded to linear like Unity's ``Color.linear``; split-toning
colours stay in gamma space, where the blend happens. Lift, gamma and gain are Unity's trackballs
``(r, g, b, w)``: a gamma-space colour and the offset slider ``w``.

Curves are control points ``((x0, y0), (x1, y1), ...)`` of monotone splines
(:mod:`torchgrade.curves`), with Unity's axes: the hue curves are periodic in hue (turns), the
others clamped at their ends; in the hue and saturation curves ``y = 0.5`` changes nothing
(hue-vs-hue adds ``y - 0.5`` turns, the saturation curves multiply saturation by ``2y``); the
master/red/green/blue curves map ``[0, 1]`` to ``[0, 1]`` in FastTonemap space ``c / (1 + max(r, g, b))``.
A curve is shared by the whole batch (no per-sample curves); its ``y`` values can be learnt.

With ``aces=True`` contrast is applied in ACEScc and the rest in ACEScg with AP1 luminance, as
Unity does when ACES tone mapping is selected. Whatever the working space, the grade returns
linear Rec.709, the one space every torchgrade stage takes and returns: ``ColorGrade(aces=True)``
followed by ``ToneMap("aces")`` reproduces Unity's ACES path (the final ``max(0)`` happens in
ACES2065-1 as in Unity), and no combination of stages can hand a curve the wrong primaries.
"""

from __future__ import annotations

import torch

from .color import (
    ACESCC_MIDGRAY,
    CHANNEL,
    REC709_LUMINANCE,
    LOGC_A,
    LOGC_B,
    LOGC_C,
    LOGC_D,
    aces_to_acescc,
    aces_to_acescg,
    aces_to_unity,
    acescc_to_aces,
    acescg_to_aces,
    hsv_to_rgb,
    linear_to_lms,
    lms_to_linear,
    luminance,
    rgb_to_hsv,
    safe_pow,
    safe_sqrt,
    srgb_to_linear,
    unity_to_aces,
    unity_to_acescg,
)
from .core import (
    HALF_MAX,
    Param,
    apply_matrix,
    check_image,
    check_range,
    color_param,
    is_constant,
    matrix_param,
    sanitize,
    scalar_param,
    to_input_dtype,
    working_dtype,
)
from .curves import curve_points, evaluate_curve
from .stage import Control, Stage, controls_signature

IDENTITY_MATRIX = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
IDENTITY_TRACKBALL = (1.0, 1.0, 1.0, 0.0)
"""A lift, gamma or gain trackball that changes nothing: white, offset 0."""


def _channels(t: torch.Tensor) -> torch.Tensor:
    """A scalar parameter (0-d or (B,1,1,1)) as a single-channel map that can be concatenated to RGB."""
    return t.reshape(t.shape[:1] + (1, 1, 1)) if t.dim() else t.reshape(1, 1, 1)


def post_exposure(image: torch.Tensor, stops: Param) -> torch.Tensor:
    """Post exposure: ``rgb · 2^stops``."""
    return image * torch.exp2(scalar_param(stops, image, "post_exposure"))


def white_balance_coefficients(temperature: torch.Tensor, tint: torch.Tensor) -> torch.Tensor:
    """LMS gains of Unity's ``ColorUtils.ColorBalanceToLMSCoeffs(temperature, tint)``.

    ``x = 0.31271 - t1·(0.1 if t1 < 0 else 0.05)``, ``y = 2.87x - 3x² - 0.27509508 + t2·0.05`` with
    ``t1 = temperature/65``, ``t2 = tint/65``; the white ``(x, y)`` goes to CAT02 LMS and the gains are
    D65's LMS ``(0.949237, 1.03542, 1.08728)`` divided by it. Returns ``(..., 3, 1, 1)``.
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
    d65 = torch.tensor((0.949237, 1.03542, 1.08728), dtype=lms.dtype, device=lms.device).reshape(3, 1, 1)
    return d65 / lms


def white_balance(image: torch.Tensor, temperature: Param = 0.0, tint: Param = 0.0) -> torch.Tensor:
    """White balance: scale in LMS by :func:`white_balance_coefficients` (Unity ``ColorGradeWhiteBalance``)."""
    gains = white_balance_coefficients(scalar_param(temperature, image, "temperature"), scalar_param(tint, image, "tint"))
    return lms_to_linear(linear_to_lms(image) * gains)


def contrast(image: torch.Tensor, amount: Param, aces: bool = False) -> torch.Tensor:
    """Contrast about mid grey in log space: ``(log(x) - 0.4135884) · (1 + amount/100) + 0.4135884``.

    Linear mode uses LogC and returns linear Rec.709; ``aces=True`` uses ACEScc and returns ACEScg
    (Unity ``ColorGradingContrast``). In LogC, ``c log10(a x + b) + d``, the encode, the scaling and
    the decode fold into one power: ``((a x + b)^k · 10^((d - 0.4135884)(k - 1) / c) - b) / a``.
    """
    k = 1.0 + scalar_param(amount, image, "contrast") * 0.01
    if aces:
        log = aces_to_acescc(unity_to_aces(image))
        return aces_to_acescg(acescc_to_aces((log - ACESCC_MIDGRAY) * k + ACESCC_MIDGRAY))
    base = (LOGC_A * image + LOGC_B).clamp_min(torch.finfo(image.dtype).tiny)
    gain = torch.pow(10.0, (LOGC_D - ACESCC_MIDGRAY) * (k - 1.0) / LOGC_C)
    return (base**k * gain - LOGC_B) / LOGC_A


def color_filter(image: torch.Tensor, color) -> torch.Tensor:
    """Colour filter: multiply by the colour, given sRGB-encoded as in Unity's picker (HDR allowed)."""
    return image * srgb_to_linear(color_param(color, image, "color_filter"))


def soft_light(base: torch.Tensor, blend: torch.Tensor) -> torch.Tensor:
    """Soft-light blend (Unity ``SoftLight``, after Adobe): below 0.5 ``2ab + a²(1 - 2b)``, else
    ``sqrt(a)(2b - 1) + 2a(1 - b)``."""
    darken = 2.0 * base * blend + base * base * (1.0 - 2.0 * blend)
    lighten = safe_sqrt(base) * (2.0 * blend - 1.0) + 2.0 * base * (1.0 - blend)
    return torch.where(blend >= 0.5, lighten, darken)


def split_toning(
    image: torch.Tensor, shadows=(0.5, 0.5, 0.5), highlights=(0.5, 0.5, 0.5), balance: Param = 0.0, luminance_weights="rec709"
) -> torch.Tensor:
    """Split toning in gamma 2.2 space (Unity ``ColorGradeSplitToning``).

    ``t = saturate(Y(saturate(c)) + balance/100)``; the shadow tint ``lerp(0.5, shadows, 1 - t)`` and the
    highlight tint ``lerp(0.5, highlights, t)`` are soft-light blended in turn. Grey 0.5 tints are neutral.
    """
    gamma = safe_pow(image, 1.0 / 2.2)
    t = (luminance(gamma.clamp(0.0, 1.0), luminance_weights) + scalar_param(balance, image, "split_balance") * 0.01).clamp(0.0, 1.0)
    shadow_tint = 0.5 + (color_param(shadows, image, "split_shadows") - 0.5) * (1.0 - t)
    highlight_tint = 0.5 + (color_param(highlights, image, "split_highlights") - 0.5) * t
    return safe_pow(soft_light(soft_light(gamma, shadow_tint), highlight_tint), 2.2)


def channel_mixer(image: torch.Tensor, mixer=IDENTITY_MATRIX) -> torch.Tensor:
    """Channel mixer: ``rgb' = M · rgb``, rows are the output channels (1.0 = Unity's 100%)."""
    return apply_matrix(matrix_param(mixer, image, "channel_mixer"), image)


def smoothstep(edge0, edge1, x: torch.Tensor) -> torch.Tensor:
    """HLSL ``smoothstep``: ``t²(3 - 2t)`` with ``t = saturate((x - edge0) / (edge1 - edge0))``."""
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
    ``rgb' = rgb · (S ws + M wm + H wh)``.
    """
    lum = luminance(image, luminance_weights)
    shadow_weight = 1.0 - smoothstep(
        scalar_param(shadows_start, image, "shadows_start"), scalar_param(shadows_end, image, "shadows_end"), lum
    )
    highlight_weight = smoothstep(
        scalar_param(highlights_start, image, "highlights_start"), scalar_param(highlights_end, image, "highlights_end"), lum
    )
    tint = (
        srgb_to_linear(color_param(shadows, image, "shadows")) * shadow_weight
        + srgb_to_linear(color_param(midtones, image, "midtones")) * (1.0 - shadow_weight - highlight_weight)
        + srgb_to_linear(color_param(highlights, image, "highlights")) * highlight_weight
    )
    return image * tint


def _trackball(value, image: torch.Tensor, name: str) -> tuple:
    """A trackball ``(r, g, b, w)``, or per sample ``(B, 4)``, as its colour and its offset ``w``."""
    t = value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=image.dtype, device=image.device)
    if t.dim() not in (1, 2) or t.shape[-1] != 4:
        raise ValueError(f"parameter {name!r} must be a trackball (r, g, b, w) or per-sample (B, 4), got shape {tuple(t.shape)}")
    return color_param(t[..., :3], image, name), scalar_param(t[..., 3], image, name)


def _minus_luminance(rgb: torch.Tensor) -> torch.Tensor:
    """``rgb - Y(rgb)`` for colours ``(..., 3, 1, 1)``, as ``sum_j w_j (rgb_i - rgb_j)`` with the Rec.709
    weights normalised to sum 1 (Unity's sum to 1.0000001), so a grey colour gives exactly 0."""
    weights = torch.tensor(REC709_LUMINANCE, dtype=rgb.dtype, device=rgb.device)
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
    """
    lift_rgb, lift_offset = _balanced(lift, image, "lift", 0.15)
    gamma_rgb, gamma_offset = _balanced(gamma, image, "gamma", 0.8)
    gain_rgb, gain_offset = _balanced(gain, image, "gain", 0.8)
    inverse_gamma = 1.0 / (gamma_rgb + gamma_offset + 1.0).clamp_min(1e-3)
    return lift_rgb + lift_offset, inverse_gamma, gain_rgb + gain_offset + 1.0


def lift_gamma_gain(image: torch.Tensor, lift=IDENTITY_TRACKBALL, gamma=IDENTITY_TRACKBALL, gain=IDENTITY_TRACKBALL) -> torch.Tensor:
    """Lift, gamma, gain (Unity ``LiftGammaGainHDR``): ``c = rgb · gain + lift``, ``sign(c) |c|^(1/gamma)``.

    The trackballs are prepared by :func:`lift_gamma_gain_coefficients`; the power is mirrored for
    negative values (ACEScg can be negative).
    """
    lift_t, inverse_gamma, gain_t = lift_gamma_gain_coefficients(lift, gamma, gain, image)
    c = image * gain_t + lift_t
    return torch.sign(c) * safe_pow(c.abs(), inverse_gamma)


def hue_shift(image: torch.Tensor, degrees: Param, hue_vs_hue=None) -> torch.Tensor:
    """Hue shift in HSV, wrapping around the colour wheel (Unity ``ColorGradingHueShift``); RGB ≥ 0.

    With a ``hue_vs_hue`` curve the shifted hue ``h`` moves on by ``curve(h) - 0.5`` turns (URP ``LutBuilderHdr``).
    """
    hue, sat, value = rgb_to_hsv(image).split(1, dim=-3)
    hue = torch.remainder(hue + scalar_param(degrees, image, "hue_shift") / 360.0, 1.0)
    if hue_vs_hue is not None:
        hue = torch.remainder(hue + evaluate_curve(hue_vs_hue, hue, periodic=True, name="hue_vs_hue") - 0.5, 1.0)
    return hsv_to_rgb(torch.cat((hue, sat, value), dim=-3))


def saturation_curves(image: torch.Tensor, hue_vs_sat=None, sat_vs_sat=None, lum_vs_sat=None, luminance_weights="rec709") -> torch.Tensor:
    """The saturation factor of the curves (URP ``LutBuilderHdr``), ``(..., 1, H, W)``; RGB ≥ 0.

    ``2 HueVsSat(h) · 2 SatVsSat(s) · 2 LumVsSat(Y)`` of the pixel's HSV hue, HSV saturation and
    luminance; curves not given count as 1.
    """
    hue, sat, _ = rgb_to_hsv(image).split(1, dim=-3)
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

    ``factor`` (from :func:`saturation_curves`) multiplies ``1 + amount/100``, as URP does.
    """
    lum = luminance(image, luminance_weights)
    scale = 1.0 + scalar_param(amount, image, "saturation") * 0.01
    return lum + (image - lum) * (scale if factor is None else scale * factor)


def fast_tonemap(image: torch.Tensor) -> torch.Tensor:
    """Unity ``FastTonemap``: ``c / (1 + max(r, g, b))`` (the max taken ≥ 0), HDR into [0, 1)."""
    return image / (1.0 + image.amax(dim=CHANNEL, keepdim=True).clamp_min(0.0))


def fast_tonemap_inverse(image: torch.Tensor) -> torch.Tensor:
    """Unity ``FastTonemapInvert``: ``c / (1 - max(r, g, b))``, the divisor kept ≥ 1/65505 (outputs ≤ 65505)."""
    return image / (1.0 - image.amax(dim=CHANNEL, keepdim=True)).clamp_min(1.0 / (1.0 + HALF_MAX))


def yrgb_curves(image: torch.Tensor, master=None, red=None, green=None, blue=None) -> torch.Tensor:
    """Master, then red/green/blue curves in FastTonemap space, then ``max(0)`` (URP ``LutBuilderHdr``).

    The master curve maps each channel; each colour curve its own. Curves not given leave values alone.
    """
    x = fast_tonemap(image)
    if master is not None:
        x = evaluate_curve(master, x, name="curve_master")
    curves = {"curve_red": red, "curve_green": green, "curve_blue": blue}
    channels = [c if p is None else evaluate_curve(p, c, name=n) for c, (n, p) in zip(x.split(1, dim=CHANNEL), curves.items())]
    return fast_tonemap_inverse(torch.cat(channels, dim=CHANNEL)).clamp_min(0.0)


# Each control, its identity value and its allowed range, in Unity's order.
CONTROLS = {
    "post_exposure": (0.0, (-20.0, 20.0)),
    "temperature": (0.0, (-100.0, 100.0)),
    "tint": (0.0, (-100.0, 100.0)),
    "contrast": (0.0, (-100.0, 100.0)),
    "color_filter": ((1.0, 1.0, 1.0), (0.0, 100.0)),
    "split_shadows": ((0.5, 0.5, 0.5), (0.0, 1.0)),
    "split_highlights": ((0.5, 0.5, 0.5), (0.0, 1.0)),
    "split_balance": (0.0, (-100.0, 100.0)),
    "channel_mixer": (IDENTITY_MATRIX, (-2.0, 2.0)),
    "shadows": ((1.0, 1.0, 1.0), (0.0, 100.0)),
    "midtones": ((1.0, 1.0, 1.0), (0.0, 100.0)),
    "highlights": ((1.0, 1.0, 1.0), (0.0, 100.0)),
    "shadows_start": (0.0, (0.0, 2.0)),
    "shadows_end": (0.3, (0.0, 2.0)),
    "highlights_start": (0.55, (0.0, 2.0)),
    "highlights_end": (1.0, (0.0, 2.0)),
    "lift": (IDENTITY_TRACKBALL, (-1.0, 1.0)),
    "gamma": (IDENTITY_TRACKBALL, (-1.0, 1.0)),
    "gain": (IDENTITY_TRACKBALL, (-1.0, 1.0)),
    "hue_shift": (0.0, (-180.0, 180.0)),
    "saturation": (0.0, (-100.0, 100.0)),
}

# Each curve control: whether it is periodic (hue, in turns) and the flat y that changes nothing
# (None: the diagonal from (0, 0) to (1, 1) changes nothing). Curves have a variable number of
# points, so they are kept out of CONTROLS (and out of ONNX graph inputs); None is identity.
CURVES = {
    "hue_vs_hue": (True, 0.5),
    "hue_vs_sat": (True, 0.5),
    "sat_vs_sat": (False, 0.5),
    "lum_vs_sat": (False, 0.5),
    "curve_master": (False, None),
    "curve_red": (False, None),
    "curve_green": (False, None),
    "curve_blue": (False, None),
}

# Which controls make each step do something; the zone limits alone change nothing.
_STEPS = {
    "post_exposure": ("post_exposure",),
    "white_balance": ("temperature", "tint"),
    "contrast": ("contrast",),
    "color_filter": ("color_filter",),
    "split_toning": ("split_shadows", "split_highlights"),
    "channel_mixer": ("channel_mixer",),
    "shadows_midtones_highlights": ("shadows", "midtones", "highlights"),
    "lift_gamma_gain": ("lift", "gamma", "gain"),
    "saturation_curves": ("hue_vs_sat", "sat_vs_sat", "lum_vs_sat"),
    "hue_shift": ("hue_shift", "hue_vs_hue"),
    "saturation": ("saturation",),
    "yrgb_curves": ("curve_master", "curve_red", "curve_green", "curve_blue"),
}


def curve_is_identity(points, flat) -> bool:
    """True for a curve that changes nothing: None, no points, all ``y == flat``, or (``flat`` None) the diagonal.

    Learnable curves (``requires_grad``) are never identity.
    """
    if points is None:
        return True
    if isinstance(points, torch.Tensor) and points.requires_grad:
        return False
    table = torch.as_tensor(points, dtype=torch.float64).reshape(-1, 2)
    if table.numel() == 0:
        return True
    x, y = table.unbind(1)
    if flat is not None:
        return bool((y == flat).all())
    return bool(x[0] == 0.0 and x[-1] == 1.0 and (y == x).all())


def is_identity_control(name: str, value) -> bool:
    """True when grading control or curve ``name`` set to ``value`` changes nothing."""
    if name in CURVES:
        return curve_is_identity(value, CURVES[name][1])
    return is_constant(value, CONTROLS[name][0])


def active_steps(params: dict) -> set:
    """The grading steps whose controls differ from identity (learnable controls always count)."""
    return {step for step, names in _STEPS.items() if any(name in params and not is_identity_control(name, params[name]) for name in names)}


def color_grade(image: torch.Tensor, aces: bool = False, **params) -> torch.Tensor:
    """The whole grade, in Unity's order; steps left at identity are not computed.

    An all-identity grade returns ``image`` itself. Otherwise the input passes the non-finite policy,
    float16/bfloat16 are computed in float32, and the result is linear Rec.709 in the input's dtype.
    """
    check_image(image)
    unknown = set(params) - set(CONTROLS) - set(CURVES)
    if unknown:
        raise ValueError(f"unknown grading control(s) {sorted(unknown)}; known: {', '.join((*CONTROLS, *CURVES))}")
    steps = active_steps(params)
    if not steps:
        return image
    p = {name: params.get(name, default) for name, (default, _) in CONTROLS.items()}
    p.update({name: None if curve_is_identity(params.get(name), flat) else params[name] for name, (_, flat) in CURVES.items()})
    weights = "ap1" if aces else "rec709"
    x = sanitize(working_dtype(image))
    if "post_exposure" in steps:
        x = post_exposure(x, p["post_exposure"])
    if "white_balance" in steps:
        x = white_balance(x, p["temperature"], p["tint"])
    if "contrast" in steps:
        x = contrast(x, p["contrast"], aces)
    elif aces:
        x = unity_to_acescg(x)
    if "color_filter" in steps:
        x = color_filter(x, p["color_filter"])
    x = x.clamp_min(0.0)
    if "split_toning" in steps:
        x = split_toning(x, p["split_shadows"], p["split_highlights"], p["split_balance"], weights)
    if "channel_mixer" in steps:
        x = channel_mixer(x, p["channel_mixer"])
    x = x.clamp_min(0.0)
    if "shadows_midtones_highlights" in steps:
        zones = [p[name] for name in ("shadows_start", "shadows_end", "highlights_start", "highlights_end")]
        x = shadows_midtones_highlights(x, p["shadows"], p["midtones"], p["highlights"], *zones, weights)
    if "lift_gamma_gain" in steps:
        x = lift_gamma_gain(x, p["lift"], p["gamma"], p["gain"]).clamp_min(0.0)
    factor = None
    if "saturation_curves" in steps:
        factor = saturation_curves(x, p["hue_vs_sat"], p["sat_vs_sat"], p["lum_vs_sat"], weights)
    if "hue_shift" in steps:
        x = hue_shift(x, p["hue_shift"], p["hue_vs_hue"])
    if "saturation" in steps or factor is not None:
        x = saturation(x, p["saturation"], weights, factor)
    if "yrgb_curves" in steps:
        x = yrgb_curves(x, p["curve_master"], p["curve_red"], p["curve_green"], p["curve_blue"])
    x = aces_to_unity(acescg_to_aces(x).clamp_min(0.0)) if aces else x.clamp_min(0.0)
    return to_input_dtype(x, image)


def _check_zone(start: Param, end: Param, zone: str) -> None:
    start_t, end_t = torch.as_tensor(start).detach(), torch.as_tensor(end).detach()
    if (start_t >= end_t).any():
        raise ValueError(f"{zone}_start must be below {zone}_end, got {start_t.tolist()} and {end_t.tolist()}")


def check_curve(name: str, points) -> None:
    """Raise ``ValueError`` naming curve ``name`` unless its points are valid: ``x`` strictly increasing in
    [0, 1] (periodic curves: [0, 1)), ``y`` in [0, 1]. None and no points are valid (identity)."""
    if points is None or (not isinstance(points, torch.Tensor) and len(points) == 0):
        return
    x, y = curve_points(points, torch.empty((), dtype=torch.float64), name)
    periodic = CURVES[name][0]
    if x[0] < 0.0 or x[-1] > 1.0 or (periodic and x[-1] >= 1.0):
        raise ValueError(f"{name} x values must lie in [0, 1{')' if periodic else ']'}, got {x.tolist()}")
    check_range(y, f"{name} y", 0.0, 1.0)


def _stored_curve(points):
    """A curve as ColorGrade keeps it: a tensor as given, a sequence as a tuple of (x, y) float pairs."""
    if points is None or isinstance(points, torch.Tensor):
        return points
    return tuple((float(x), float(y)) for x, y in points)


class ColorGrade(Stage):
    """Colour grading layer with Unity's controls (see the module docstring for order and units).

    Every control accepts a number (colour: a triple; trackball: ``(r, g, b, w)``; mixer: a 3x3
    nested sequence), a tensor, a per-sample tensor ``(B,)``/``(B, 3)``/``(B, 4)``/``(B, 3, 3)``, or
    an ``nn.Parameter`` to learn it. Curves (:data:`CURVES`) take control points ``((x, y), ...)``
    or an ``(N, 2)`` tensor, shared by the batch. Controls left at identity cost nothing; an
    all-identity grade returns its input unchanged.

    Examples:
        >>> import torch
        >>> grade = ColorGrade(contrast=20, saturation=-100)
        >>> out = grade(torch.rand(1, 3, 4, 4))
        >>> bool(torch.allclose(out[:, 0], out[:, 1], atol=1e-5))  # saturation -100: grey
        True
        >>> ColorGrade().is_identity
        True
    """

    controls = {
        "aces": Control(False),
        **{name: Control(default, allowed) for name, (default, allowed) in CONTROLS.items()},
        **{name: Control(None) for name in CURVES},
    }

    def __init__(self, aces: bool = False, **controls):
        super().__init__()
        self.init_controls(aces=bool(aces), **controls)

    def check_control(self, name: str, value):
        if name in CURVES:
            check_curve(name, value)
            return _stored_curve(value)
        return value

    def check_together(self) -> None:
        _check_zone(self.shadows_start, self.shadows_end, "shadows")
        _check_zone(self.highlights_start, self.highlights_end, "highlights")

    def is_default(self, name: str) -> bool:
        if name == "aces":
            return not self.aces
        return is_identity_control(name, getattr(self, name))

    @property
    def is_identity(self) -> bool:
        """True when no control changes the image (the layer is then skipped and not exported)."""
        return not active_steps(self.params())

    def curves(self) -> dict:
        """The curves that change something, by name (as stored)."""
        return {name: getattr(self, name) for name in CURVES if not self.is_default(name)}

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        self.check_learnable()
        return color_grade(image, **self.params())


ColorGrade.__signature__ = controls_signature(ColorGrade.controls)
