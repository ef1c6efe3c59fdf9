"""ColorGrade against a pixel-by-pixel float64 re-implementation of Unity's ColorGrade, plus invariants."""

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade import functional as F

from reference.pixels import EXTREMES, pixels, rows
from reference.grade import MID, sample_pixels, unity_grade


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


@pytest.mark.parametrize("aces", [False, True], ids=["linear", "aces"])
@pytest.mark.parametrize("look", sorted(LOOKS))
def test_matches_unity_color_grade_reference(look, aces, device):
    rgb = sample_pixels()
    ours = rows(tg.ColorGrade(aces=aces, **LOOKS[look])(pixels(rgb, device=device)))
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
    """A turn is outside the stage's ±180 (a number is refused): given as a tensor, which the function takes unread."""
    image = torch.rand(2, 3, 6, 6, dtype=torch.float64) * 3
    torch.testing.assert_close(F.hue_shift(image, torch.tensor(degrees, dtype=torch.float64)), image, atol=1e-12, rtol=1e-12)


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


def test_per_sample_controls_equal_separate_runs(device):
    image = torch.rand(3, 3, 5, 4, dtype=torch.float64, device=device) * 4
    contrast = torch.tensor([-20.0, 0.0, 40.0], dtype=torch.float64)
    tint = torch.tensor([[1.0, 0.9, 0.8], [1.0, 1.0, 1.0], [0.7, 0.8, 1.0]], dtype=torch.float64)
    mixer = torch.eye(3, dtype=torch.float64).repeat(3, 1, 1)
    mixer[2, 0, 1] = 0.3
    batched = tg.ColorGrade(contrast=contrast, color_filter=tint, channel_mixer=mixer).to(device)(image)
    for i in range(3):
        single = tg.ColorGrade(contrast=contrast[i].item(), color_filter=tint[i].tolist(), channel_mixer=mixer[i].tolist())
        torch.testing.assert_close(batched[i : i + 1], single(image[i : i + 1]))


def test_per_sample_batch_mismatch_is_a_clear_error():
    with pytest.raises(ValueError, match="contrast"):
        tg.ColorGrade(contrast=torch.tensor([10.0, 20.0]))(torch.rand(3, 3, 4, 4))


def test_learnable_controls_are_parameters_with_gradients(device):
    grade = tg.ColorGrade(contrast=torch.nn.Parameter(torch.tensor(10.0)), color_filter=torch.nn.Parameter(torch.tensor([0.9, 1.0, 1.0])))
    assert {name for name, _ in grade.named_parameters()} == {"contrast", "color_filter"}
    assert not grade.is_identity
    grade.to(device)(torch.rand(2, 3, 4, 4, device=device) * 2).sum().backward()
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


def extremes_image(dtype=torch.float32, device=None):
    values = EXTREMES + [1e-45, 1e-38, 59.9, 1e3, 3e38, -1.0, -1e30]
    grid = [[a, b, c] for a in values for b in (0.0, 0.18, 65504.0) for c in (0.0, 1e30)]
    return pixels(grid, dtype, device)


@pytest.mark.parametrize("aces", [False, True], ids=["linear", "aces"])
def test_extremes_give_finite_outputs_and_gradients(aces, device):
    image = extremes_image(device=device).requires_grad_()
    out = tg.ColorGrade(aces=aces, **LOOKS["everything"])(image)
    assert torch.isfinite(out).all() and (out >= 0).all() if not aces else torch.isfinite(out).all()
    out.sum().backward()
    assert torch.isfinite(image.grad).all()


def test_nan_and_inf_pixels_do_not_spread(device):
    image = torch.rand(1, 3, 4, 4, device=device) * 4
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
        grade(torch.rand(1, 5, 2, 2))
    with pytest.raises(TypeError, match="floating-point"):
        grade(torch.ones(1, 3, 2, 2, dtype=torch.uint8))
    with pytest.raises(ValueError, match="empty"):
        grade(torch.rand(0, 3, 2, 2))


def test_config_lists_only_what_changed():
    assert tg.ColorGrade(contrast=20, aces=True).to_config() == {"aces": True, "contrast": 20}
    assert tg.ColorGrade().to_config() == {}


def test_acescc_contrast_in_half_precision_stays_finite_at_the_top_of_the_range():
    """The folded contrast bounds the power at 65504 after taking it too: in float16 ln(65504) rounds up, whose
    exponential is infinite, and the decode's difference of an infinity with itself is NaN."""
    from torchgrade.grading.steps import log_contrast

    x = torch.tensor([1000.0, 5000.0, 65504.0], dtype=torch.float16)
    with torch.no_grad():
        out = log_contrast(x, 30.0, "acescc")
    expected = log_contrast(x.double(), 30.0, "acescc").clamp(max=65504.0)
    assert out.dtype == torch.float16 and torch.isfinite(out).all()
    torch.testing.assert_close(out.double(), expected, rtol=1e-2, atol=0.0)  # a float16 log2 and exp2: 0.4 % at 1000
