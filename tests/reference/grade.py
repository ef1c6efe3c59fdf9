"""Unity's colour grade written pixel by pixel in float64 (ColorGrading.hlsl, LutBuilderHdr), and its samples."""

import colorsys
import math

import numpy as np

from .pixels import LUM709, random_rgb
from .tonemap import AP0_2_AP1, AP1_Y, SRGB_2_AP0

LIN_2_LMS = np.array([[3.90405e-1, 5.49941e-1, 8.92632e-3], [7.08416e-2, 9.63172e-1, 1.35775e-3], [2.31082e-2, 1.28021e-1, 9.36245e-1]])
LMS_2_LIN = np.array([[2.85847e0, -1.62879e0, -2.48910e-2], [-2.10182e-1, 1.15820e0, 3.24281e-4], [-4.18120e-2, -1.18169e-1, 1.06867e0]])
MID = 0.4135884


def srgb_decode(c):
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def lms_coeffs(temperature, tint):
    t1, t2 = temperature / 65, tint / 65
    x = 0.31271 - t1 * (0.1 if t1 < 0 else 0.05)
    y = 2.87 * x - 3 * x * x - 0.27509508 + t2 * 0.05
    big_x, big_z = x / y, (1 - x - y) / y
    lms = np.array([0.7328 * big_x + 0.4296 - 0.1624 * big_z, -0.7036 * big_x + 1.6975 + 0.0061 * big_z, 0.0030 * big_x + 0.0136 + 0.9834 * big_z])
    return np.array([0.949237, 1.03542, 1.08728]) / lms


def logc(x):
    return 0.244161 * math.log10(max(5.555556 * x + 0.047996, 1e-300)) + 0.386036


def logc_inv(x):
    return (10 ** ((x - 0.386036) / 0.244161) - 0.047996) / 5.555556


def acescc(x):
    x = min(max(x, 0.0), 65504.0)
    return (math.log2(2**-16 + x * 0.5) + 9.72) / 17.52 if x < 2**-15 else (math.log2(x) + 9.72) / 17.52


def acescc_inv(x):
    if x < (9.72 - 15) / 17.52:
        return (2 ** (x * 17.52 - 9.72) - 2**-16) * 2
    if x < (math.log2(65504) + 9.72) / 17.52:
        return 2 ** (x * 17.52 - 9.72)
    return 65504.0


def soft_light(base, blend):
    return np.where(
        blend >= 0.5,
        np.sqrt(base) * (2 * blend - 1) + 2 * base * (1 - blend),
        2 * base * blend + base * base * (1 - 2 * blend),
    )


def smoothstep(a, b, x):
    t = min(max((x - a) / (b - a), 0), 1)
    return t * t * (3 - 2 * t)


DEFAULTS = dict(
    post_exposure=0.0, temperature=0.0, tint=0.0, contrast=0.0, color_filter=(1, 1, 1),
    split_shadows=(0.5, 0.5, 0.5), split_highlights=(0.5, 0.5, 0.5), split_balance=0.0,
    channel_mixer=np.eye(3), shadows=(1, 1, 1), midtones=(1, 1, 1), highlights=(1, 1, 1),
    shadows_start=0.0, shadows_end=0.3, highlights_start=0.55, highlights_end=1.0, hue_shift=0.0, saturation=0.0,
)


def unity_grade_pixel(rgb, aces=False, **controls):
    """Unity's ColorGrade (Catlike Coding Color Grading listings; ColorUtils.ColorBalanceToLMSCoeffs) on one pixel."""
    p = {**DEFAULTS, **controls}
    lum_weights = AP1_Y if aces else LUM709
    c = np.array(rgb, dtype=np.float64) * 2.0 ** p["post_exposure"]
    if p["temperature"] or p["tint"]:  # torchgrade skips identity steps; Unity's 6-digit LMS round trip is off by 2e-4
        c = LMS_2_LIN @ ((LIN_2_LMS @ c) * lms_coeffs(p["temperature"], p["tint"]))
    k = 1 + p["contrast"] / 100
    if aces:
        log = np.array([acescc(v) for v in SRGB_2_AP0 @ c])
        c = AP0_2_AP1 @ np.array([acescc_inv((v - MID) * k + MID) for v in log])
    else:
        c = np.array([logc_inv((logc(v) - MID) * k + MID) for v in c])
    c = c * np.array([srgb_decode(v) for v in p["color_filter"]])
    c = np.maximum(c, 0)
    g = c ** (1 / 2.2)
    t = min(max(np.clip(g, 0, 1) @ lum_weights + p["split_balance"] / 100, 0), 1)
    g = soft_light(g, 0.5 + (np.array(p["split_shadows"]) - 0.5) * (1 - t))
    g = soft_light(g, 0.5 + (np.array(p["split_highlights"]) - 0.5) * t)
    c = np.maximum(np.asarray(p["channel_mixer"], dtype=np.float64) @ (g**2.2), 0)
    lum = c @ lum_weights
    ws = 1 - smoothstep(p["shadows_start"], p["shadows_end"], lum)
    wh = smoothstep(p["highlights_start"], p["highlights_end"], lum)
    def decode(col):
        return np.array([srgb_decode(v) for v in col])
    c = c * (decode(p["shadows"]) * ws + decode(p["midtones"]) * (1 - ws - wh) + decode(p["highlights"]) * wh)
    h, s, v = colorsys.rgb_to_hsv(*c)
    c = np.array(colorsys.hsv_to_rgb((h + p["hue_shift"] / 360) % 1.0, s, v))
    lum = c @ lum_weights
    c = lum + (c - lum) * (1 + p["saturation"] / 100)
    if aces:
        ap1_to_ap0 = np.linalg.inv(AP0_2_AP1)
        return np.linalg.inv(SRGB_2_AP0) @ np.maximum(ap1_to_ap0 @ c, 0)
    return np.maximum(c, 0)


def unity_grade(rgb, aces=False, **controls):
    return np.array([unity_grade_pixel(p, aces, **controls) for p in rgb])


def sample_pixels():
    rgb = random_rgb(250, high=1.0, seed=7) ** 2 * 12.0
    rgb[:6] = np.array([0.0, 0.05, 0.18, 1.0, 5.0, 50.0])[:, None]
    return rgb
