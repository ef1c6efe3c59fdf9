"""The pure, differentiable functions behind torchgrade's modules, in one namespace.

Examples:
    >>> import torch
    >>> from torchgrade import functional as F
    >>> image = torch.rand(1, 3, 4, 4) * 8
    >>> out = F.tonemap(F.color_grade(image, contrast=20), "neutral")
    >>> bool(out.min() >= 0 and out.max() <= 1)
    True
"""

from .bloom import bloom, bloom_threshold, convolution_bloom, fft_convolve
from .color import (
    aces_to_acescc,
    aces_to_acescg,
    aces_to_unity,
    acescc_to_aces,
    acescct_to_linear,
    acescg_to_aces,
    acescg_to_unity,
    hlg_inverse_oetf,
    hlg_oetf,
    hsv_to_rgb,
    linear_to_acescct,
    linear_to_lms,
    linear_to_logc,
    linear_to_pq,
    linear_to_srgb,
    lms_to_linear,
    logc_to_linear,
    luminance,
    pq_to_linear,
    rgb_to_hsv,
    srgb_to_linear,
    unity_to_aces,
    unity_to_acescg,
)
from .exposure import (
    adapt_luminance,
    area_resize,
    auto_exposure,
    exposure_operator,
    halving_average,
    meter_luminance,
)
from .grading.curves import evaluate_curve, monotone_tangents
from .grading.grade import color_grade
from .grading.primary import (
    brightness,
    linear_contrast,
    log_gamma,
    offset_exposure,
    primary_grade,
    primary_log_contrast,
    primary_saturation,
)
from .grading.steps import (
    channel_mixer,
    color_filter,
    contrast,
    fast_tonemap,
    fast_tonemap_inverse,
    hue_shift,
    lift_gamma_gain,
    lift_gamma_gain_coefficients,
    post_exposure,
    saturation,
    saturation_curves,
    shadows_midtones_highlights,
    split_toning,
    white_balance,
    white_balance_coefficients,
    yrgb_curves,
)
from .lut import apply_lut
from .output.dither import dither, dither_pattern
from .tonemap import (
    aces,
    aces2_hdr,
    aces2_sdr,
    aces_hill,
    aces_narkowicz,
    aces_reference,
    agx,
    agx_godot,
    filmic,
    hable,
    khronos_pbr_neutral,
    neutral,
    reinhard,
    reinhard_extended,
    reinhard_luminance,
    tonemap,
    unreal_filmic,
)
from .tonemap.aces2 import aces2_output

__all__ = [
    "acescct_to_linear",
    "hlg_inverse_oetf",
    "hlg_oetf",
    "linear_to_acescct",
    "linear_to_pq",
    "pq_to_linear",
    "aces2_sdr",
    "aces2_hdr",
    "aces2_output",
    "aces_to_acescc",
    "aces_to_acescg",
    "aces_to_unity",
    "acescc_to_aces",
    "acescg_to_aces",
    "acescg_to_unity",
    "hsv_to_rgb",
    "linear_to_lms",
    "linear_to_logc",
    "linear_to_srgb",
    "lms_to_linear",
    "logc_to_linear",
    "luminance",
    "rgb_to_hsv",
    "srgb_to_linear",
    "unity_to_aces",
    "unity_to_acescg",
    "tonemap",
    "reinhard",
    "reinhard_extended",
    "reinhard_luminance",
    "neutral",
    "aces",
    "hable",
    "filmic",
    "unreal_filmic",
    "aces_reference",
    "aces_hill",
    "aces_narkowicz",
    "agx",
    "agx_godot",
    "khronos_pbr_neutral",
    "color_grade",
    "post_exposure",
    "white_balance",
    "white_balance_coefficients",
    "contrast",
    "color_filter",
    "split_toning",
    "channel_mixer",
    "shadows_midtones_highlights",
    "lift_gamma_gain",
    "lift_gamma_gain_coefficients",
    "saturation_curves",
    "hue_shift",
    "saturation",
    "fast_tonemap",
    "fast_tonemap_inverse",
    "yrgb_curves",
    "evaluate_curve",
    "monotone_tangents",
    "primary_grade",
    "offset_exposure",
    "brightness",
    "linear_contrast",
    "primary_log_contrast",
    "log_gamma",
    "primary_saturation",
    "dither",
    "dither_pattern",
    "auto_exposure",
    "meter_luminance",
    "adapt_luminance",
    "exposure_operator",
    "area_resize",
    "halving_average",
    "bloom",
    "bloom_threshold",
    "convolution_bloom",
    "fft_convolve",
    "apply_lut",
]


def __getattr__(name: str):
    if name == "log_contrast":  # OpenColorIO's log contrast, named apart from Unity's (grading.steps.log_contrast)
        import warnings

        warnings.warn("torchgrade.functional.log_contrast is now primary_log_contrast; the old name goes in the next release",
                      DeprecationWarning, stacklevel=2)
        return primary_log_contrast
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
