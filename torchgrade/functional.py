"""The pure, differentiable functions behind torchgrade's modules, in one namespace."""

from .color import (
    aces_to_acescc,
    aces_to_acescg,
    aces_to_unity,
    acescc_to_aces,
    acescg_to_aces,
    acescg_to_unity,
    hsv_to_rgb,
    linear_to_lms,
    linear_to_logc,
    linear_to_srgb,
    lms_to_linear,
    logc_to_linear,
    luminance,
    rgb_to_hsv,
    srgb_to_linear,
    unity_to_aces,
    unity_to_acescg,
)
from .tonemap import (
    tonemap,
    reinhard,
    reinhard_extended,
    reinhard_luminance,
    neutral,
    aces,
    hable,
    filmic,
    unreal_filmic,
    aces_reference,
    aces_hill,
    aces_narkowicz,
    agx,
    agx_godot,
    khronos_pbr_neutral,
)
from .grade import (
    color_grade,
    post_exposure,
    white_balance,
    white_balance_coefficients,
    contrast,
    color_filter,
    split_toning,
    channel_mixer,
    shadows_midtones_highlights,
    lift_gamma_gain,
    lift_gamma_gain_coefficients,
    saturation_curves,
    hue_shift,
    saturation,
    fast_tonemap,
    fast_tonemap_inverse,
    yrgb_curves,
)
from .curves import evaluate_curve, monotone_tangents
from .primary import primary_grade, offset_exposure, brightness, linear_contrast, log_contrast, log_gamma, primary_saturation
from .dither import dither, dither_pattern
from .exposure import auto_exposure, meter_luminance, adapt_luminance, exposure_operator, area_resize, halving_average
from .bloom import bloom, bloom_threshold, convolution_bloom, fft_convolve
from .lut import apply_lut
