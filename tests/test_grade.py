"""ColorGrade against a pixel-by-pixel float64 re-implementation of Unity's ColorGrade, plus invariants."""

import colorsys
import math

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade import functional as F

from test_color import EXTREMES, pixels, random_rgb, rows
from test_tonemap import AP0_2_AP1, AP1_Y, SRGB_2_AP0

LUM709 = np.array([0.2126729, 0.7151522, 0.0721750])
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
    decode = lambda col: np.array([srgb_decode(v) for v in col])
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


LOOKS = {
    "exposure": dict(post_exposure=1.3),
    "white_balance": dict(temperature=40, tint=-25),
    "cool": dict(temperature=-60, tint=30),
    "contrast": dict(contrast=45),
    "low_contrast": dict(contrast=-70),
    "filter": dict(color_filter=(1.0, 0.8, 0.6)),
    "split": dict(split_shadows=(0.2, 0.4, 0.8), split_highlights=(0.9, 0.6, 0.3), split_balance=-30),
    "mixer": dict(channel_mixer=((0.8, 0.3, -0.1), (0.1, 0.9, 0.0), (-0.2, 0.2, 1.1))),
    "zones": dict(shadows=(0.8, 0.9, 1.2), midtones=(1.1, 1.0, 0.9), highlights=(1.2, 1.1, 0.8), shadows_end=0.4, highlights_start=0.5),
    "hue": dict(hue_shift=-75),
    "saturation": dict(saturation=60),
    "everything": dict(
        post_exposure=0.4, temperature=20, tint=5, contrast=30, color_filter=(0.95, 1.0, 0.9),
        split_shadows=(0.4, 0.5, 0.6), split_highlights=(0.6, 0.5, 0.4), split_balance=10,
        channel_mixer=((1.0, 0.05, 0.0), (0.0, 1.0, 0.05), (0.05, 0.0, 1.0)), shadows=(0.9, 0.95, 1.1),
        midtones=(1.05, 1.0, 0.95), highlights=(1.1, 1.0, 0.9), hue_shift=12, saturation=20,
    ),
}


def sample_pixels():
    rgb = random_rgb(250, high=1.0, seed=7) ** 2 * 12.0
    rgb[:6] = np.array([0.0, 0.05, 0.18, 1.0, 5.0, 50.0])[:, None]
    return rgb


@pytest.mark.parametrize("aces", [False, True], ids=["linear", "aces"])
@pytest.mark.parametrize("look", sorted(LOOKS))
def test_matches_unity_color_grade_reference(look, aces):
    rgb = sample_pixels()
    ours = rows(tg.ColorGrade(aces=aces, **LOOKS[look])(pixels(rgb)))
    np.testing.assert_allclose(ours, unity_grade(rgb, aces, **LOOKS[look]), rtol=1e-9, atol=1e-9)


def test_white_balance_coefficients_are_one_at_zero():
    gains = F.white_balance_coefficients(torch.tensor(0.0, dtype=torch.float64), torch.tensor(0.0, dtype=torch.float64))
    torch.testing.assert_close(gains.flatten(), torch.ones(3, dtype=torch.float64), atol=2e-5, rtol=0)


def test_identity_grade_is_the_input_itself():
    image = torch.rand(2, 3, 5, 6)
    for aces in (False, True):
        grade = tg.ColorGrade(aces=aces)
        assert grade.is_identity and grade(image) is image


def test_zone_limits_alone_change_nothing():
    image = torch.rand(1, 3, 4, 4)
    assert tg.ColorGrade(shadows_end=0.5, highlights_start=0.7)(image) is image


def test_saturation_minus_100_gives_luminance_grey():
    image = torch.rand(2, 3, 6, 6, dtype=torch.float64) * 3
    out = F.saturation(image, -100.0)
    torch.testing.assert_close(out, tg.color.luminance(image).expand_as(out))


@pytest.mark.parametrize("degrees", [360.0, -360.0])
def test_full_turn_hue_shift_is_identity(degrees):
    image = torch.rand(2, 3, 6, 6, dtype=torch.float64) * 3
    torch.testing.assert_close(F.hue_shift(image, degrees), image, atol=1e-12, rtol=1e-12)


def test_hue_shift_of_120_degrees_turns_red_into_green():
    red = pixels([[2.0, 0.0, 0.0]])
    torch.testing.assert_close(F.hue_shift(red, 120.0), pixels([[0.0, 2.0, 0.0]]), atol=1e-12, rtol=0)


def test_contrast_pivots():
    # ACEScc's pivot 0.4135884 is 18% grey; in LogC the same code value is linear 0.2248 (LogC^-1 of it).
    pivot_logc = (10 ** ((MID - 0.386036) / 0.244161) - 0.047996) / 5.555556
    grey = pixels([[pivot_logc] * 3])
    torch.testing.assert_close(F.contrast(grey, 60.0), grey, atol=1e-12, rtol=0)
    aces_grey = pixels([[0.18] * 3])
    out = F.contrast(tg.color.aces_to_unity(aces_grey), 60.0, aces=True)
    # 0.4135884 is ACEScc(0.18) rounded to 7 digits, hence the 1e-8 tolerance.
    torch.testing.assert_close(tg.color.acescg_to_aces(out), aces_grey, atol=1e-8, rtol=0)


def test_contrast_increases_spread_in_log_space():
    ramp = pixels([[v] * 3 for v in (0.02, 0.1, 0.5, 2.0)])
    more = rows(F.contrast(ramp, 50.0))[:, 0]
    assert more[0] < 0.02 and more[-1] > 2.0 and np.all(np.diff(more) > 0)


def test_per_sample_controls_equal_separate_runs():
    image = torch.rand(3, 3, 5, 4, dtype=torch.float64) * 4
    contrast = torch.tensor([-20.0, 0.0, 40.0], dtype=torch.float64)
    tint = torch.tensor([[1.0, 0.9, 0.8], [1.0, 1.0, 1.0], [0.7, 0.8, 1.0]], dtype=torch.float64)
    mixer = torch.eye(3, dtype=torch.float64).repeat(3, 1, 1)
    mixer[2, 0, 1] = 0.3
    batched = tg.ColorGrade(contrast=contrast, color_filter=tint, channel_mixer=mixer)(image)
    for i in range(3):
        single = tg.ColorGrade(contrast=contrast[i].item(), color_filter=tint[i].tolist(), channel_mixer=mixer[i].tolist())
        torch.testing.assert_close(batched[i : i + 1], single(image[i : i + 1]))


def test_per_sample_batch_mismatch_is_a_clear_error():
    with pytest.raises(ValueError, match="contrast"):
        tg.ColorGrade(contrast=torch.tensor([10.0, 20.0]))(torch.rand(3, 3, 4, 4))


def test_learnable_controls_are_parameters_with_gradients():
    grade = tg.ColorGrade(contrast=torch.nn.Parameter(torch.tensor(10.0)), color_filter=torch.nn.Parameter(torch.tensor([0.9, 1.0, 1.0])))
    assert {name for name, _ in grade.named_parameters()} == {"contrast", "color_filter"}
    assert not grade.is_identity
    grade(torch.rand(2, 3, 4, 4) * 2).sum().backward()
    assert torch.isfinite(grade.contrast.grad) and torch.isfinite(grade.color_filter.grad).all()


FUNCTIONAL_OPS = {
    "post_exposure": (F.post_exposure, lambda: (torch.tensor(0.7, dtype=torch.float64),)),
    "white_balance": (F.white_balance, lambda: (torch.tensor(30.0, dtype=torch.float64), torch.tensor(-10.0, dtype=torch.float64))),
    "contrast": (F.contrast, lambda: (torch.tensor(25.0, dtype=torch.float64),)),
    "contrast_aces": (lambda x, a: F.contrast(x, a, aces=True), lambda: (torch.tensor(25.0, dtype=torch.float64),)),
    "color_filter": (F.color_filter, lambda: (torch.tensor([0.9, 0.7, 1.2], dtype=torch.float64),)),
    "split_toning": (F.split_toning, lambda: (torch.tensor([0.3, 0.4, 0.7], dtype=torch.float64), torch.tensor([0.8, 0.6, 0.4], dtype=torch.float64), torch.tensor(15.0, dtype=torch.float64))),
    "channel_mixer": (F.channel_mixer, lambda: (torch.tensor([[0.9, 0.1, 0.0], [0.0, 1.0, 0.2], [0.1, 0.0, 0.8]], dtype=torch.float64),)),
    "zones": (F.shadows_midtones_highlights, lambda: (torch.tensor([0.8, 0.9, 1.1], dtype=torch.float64), torch.tensor([1.1, 1.0, 0.9], dtype=torch.float64), torch.tensor([1.2, 1.0, 0.8], dtype=torch.float64))),
    "hue_shift": (F.hue_shift, lambda: (torch.tensor(40.0, dtype=torch.float64),)),
    "saturation": (F.saturation, lambda: (torch.tensor(35.0, dtype=torch.float64),)),
}


@pytest.mark.parametrize("name", sorted(FUNCTIONAL_OPS))
def test_gradcheck_image_and_parameters(name):
    op, make_params = FUNCTIONAL_OPS[name]
    image = (torch.rand(1, 3, 3, 3, dtype=torch.float64) * 1.5 + 0.05).requires_grad_()
    params = tuple(p.requires_grad_() for p in make_params())
    assert torch.autograd.gradcheck(op, (image,) + params)


def extremes_image(dtype=torch.float32):
    values = EXTREMES + [1e-45, 1e-38, 59.9, 1e3, 3e38, -1.0, -1e30]
    grid = [[a, b, c] for a in values for b in (0.0, 0.18, 65504.0) for c in (0.0, 1e30)]
    return pixels(grid, dtype)


@pytest.mark.parametrize("aces", [False, True], ids=["linear", "aces"])
def test_extremes_give_finite_outputs_and_gradients(aces):
    image = extremes_image().requires_grad_()
    out = tg.ColorGrade(aces=aces, **LOOKS["everything"])(image)
    assert torch.isfinite(out).all() and (out >= 0).all() if not aces else torch.isfinite(out).all()
    out.sum().backward()
    assert torch.isfinite(image.grad).all()


def test_nan_and_inf_pixels_do_not_spread():
    image = torch.rand(1, 3, 4, 4) * 4
    image[0, :, 2, 3] = torch.tensor([float("nan"), float("inf"), -float("inf")])
    out = tg.ColorGrade(**LOOKS["everything"])(image)
    assert torch.isfinite(out).all()
    clean = image.clone()
    clean[0, :, 2, 3] = 0.3
    expected = tg.ColorGrade(**LOOKS["everything"])(clean)
    torch.testing.assert_close(out[..., :2, :], expected[..., :2, :])


@pytest.mark.parametrize("dtype, tolerance", [(torch.float16, 2e-2), (torch.bfloat16, 6e-2)])
def test_low_precision_inputs_are_graded_in_float32(dtype, tolerance):
    image = torch.rand(1, 3, 8, 8) * 8
    out = tg.ColorGrade(**LOOKS["everything"])(image.to(dtype))
    assert out.dtype == dtype and torch.isfinite(out).all()
    reference = tg.ColorGrade(**LOOKS["everything"])(image.to(dtype).float())
    assert ((out.float() - reference).abs() / (1 + reference.abs())).max() <= tolerance


@pytest.mark.parametrize(
    "controls, message",
    [
        (dict(contrast=150), r"contrast must lie in \[-100.0, 100.0\]"),
        (dict(hue_shift=-200), "hue_shift"),
        (dict(split_shadows=(0.5, 1.5, 0.5)), "split_shadows"),
        (dict(shadows_start=0.5, shadows_end=0.2), "shadows_start must be below shadows_end"),
        (dict(brightness=3), "unknown ColorGrade control"),
        (dict(channel_mixer=((1, 0), (0, 1))), "channel_mixer"),
    ],
)
def test_bad_controls_name_the_parameter(controls, message):
    with pytest.raises(ValueError, match=message):
        tg.ColorGrade(**controls)(torch.rand(1, 3, 2, 2))


def test_bad_images_raise_clear_errors():
    grade = tg.ColorGrade(contrast=10)
    with pytest.raises(ValueError, match="3 colour channels"):
        grade(torch.rand(1, 4, 2, 2))
    with pytest.raises(TypeError, match="floating-point"):
        grade(torch.ones(1, 3, 2, 2, dtype=torch.uint8))
    with pytest.raises(ValueError, match="empty"):
        grade(torch.rand(0, 3, 2, 2))


def test_config_lists_only_what_changed():
    assert tg.ColorGrade(contrast=20, aces=True).to_config() == {"aces": True, "contrast": 20}
    assert tg.ColorGrade().to_config() == {}
