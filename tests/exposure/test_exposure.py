"""AutoExposure: metering, temporal adaptation, the middle-grey operators, robustness, ONNX export.

Expected values come from formulas written here in float64 (Rec.709 luminance, the log-average,
the closed-form exponential, Reinhard's Eq. 4), not from the code under test.
"""

import math

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.exposure.adaptation import MAX_ADAPTED, MIN_LUMINANCE
from torchgrade.functional import adapt_luminance, auto_exposure, exposure_operator, meter_luminance

REC709 = torch.tensor([0.2126729, 0.7151522, 0.0721750], dtype=torch.float64)
DELTA = 1e-4  # Reinhard's δ of the log-average


def lum(image: torch.Tensor) -> torch.Tensor:
    """Rec.709 luminance in float64, shape (..., H, W)."""
    return torch.einsum("...chw,c->...hw", image.double(), REC709.to(image.device))


def uniform(luminances, size=(8, 8), dtype=torch.float64, device=None) -> torch.Tensor:
    """Grey frames (B, 3, H, W) whose luminance is each value of ``luminances``."""
    values = torch.as_tensor(luminances, dtype=dtype, device=device) / REC709.sum().to(dtype)
    return values.reshape(-1, 1, 1, 1).expand(-1, 3, *size).clone()


def expected_log_average(image: torch.Tensor) -> torch.Tensor:
    """exp(mean(log(δ + L))) - δ per image, in float64."""
    return torch.exp(torch.log(DELTA + lum(image).clamp_min(0)).mean((-2, -1))) - DELTA


# ---------------------------------------------------------------- metering


@pytest.mark.parametrize("size", [(1, 1), (7, 5), (64, 64), (200, 130)])
def test_metering_matches_the_direct_averages_at_any_size(size, device):
    image = torch.rand(2, 3, *size, dtype=torch.float64, device=device) * 4
    torch.testing.assert_close(meter_luminance(image, "mean"), lum(image).mean((-2, -1)), rtol=1e-12, atol=0)
    torch.testing.assert_close(meter_luminance(image, "log"), expected_log_average(image), rtol=1e-12, atol=0)


def test_log_metering_barely_moves_for_one_huge_pixel():
    grey = torch.full((1, 3, 64, 64), 0.18)
    spike = grey.clone()
    spike[..., 10, 20] = 1e6
    base, log_spike, mean_spike = meter_luminance(grey, "log"), meter_luminance(spike, "log"), meter_luminance(spike, "mean")
    assert abs(log_spike / base - 1) < 0.01
    assert mean_spike / meter_luminance(grey, "mean") > 10  # the arithmetic mean is dragged far away


def test_metering_ignores_non_finite_pixels_by_policy(device):
    image = torch.rand(1, 3, 16, 16, device=device) + 0.1
    bad = image.clone()
    bad[0, :, 3, 4] = float("nan")
    replaced = image.clone()
    replaced[0, :, 3, 4] = 0.0  # NaN -> 0 is the library's policy
    for metering in ("mean", "log"):
        torch.testing.assert_close(meter_luminance(bad, metering), meter_luminance(replaced, metering))


# ---------------------------------------------------------------- temporal adaptation


def test_dt_zero_keeps_the_state():
    module = tg.AutoExposure(metering="mean")
    module(uniform([0.5]))
    first = module.adapted_luminance.clone()
    module(uniform([8.0]), dt=0.0)
    assert torch.equal(module.adapted_luminance, first)
    _, new = auto_exposure(uniform([8.0]), torch.tensor([0.5], dtype=torch.float64), 0.0)
    assert new.item() == 0.5


def test_first_frame_adapts_instantly_and_reset_forgets():
    module = tg.AutoExposure(metering="mean")
    module(uniform([0.5]))
    torch.testing.assert_close(module.adapted_luminance, torch.tensor([0.5], dtype=torch.float64))
    module.reset()
    assert module.adapted_luminance.numel() == 0
    module(uniform([3.0]), dt=0.01)
    torch.testing.assert_close(module.adapted_luminance, torch.tensor([3.0], dtype=torch.float64))


@pytest.mark.parametrize("metering", ["mean", "log"])
def test_state_follows_the_closed_form_exponential(metering, device):
    speed, dt, steps, start, target = 2.0, 0.05, 10, 0.5, 4.0
    module = tg.AutoExposure(speed=speed, metering=metering).to(device)
    module(uniform([start], device=device))
    for _ in range(steps):
        module(uniform([target], device=device), dt=dt)
    expected = target + (start - target) * math.exp(-speed * dt * steps)
    assert module.adapted_luminance.item() == pytest.approx(expected, rel=1e-9)


def test_separate_speeds_for_brightening_and_darkening():
    to_light, to_dark = 3.0, 0.5
    module = tg.AutoExposure(speed=100.0, speed_to_light=to_light, speed_to_dark=to_dark, metering="mean")
    module(uniform([1.0]))
    module(uniform([5.0]), dt=0.2)
    brighter = 5.0 + (1.0 - 5.0) * math.exp(-to_light * 0.2)
    assert module.adapted_luminance.item() == pytest.approx(brighter, rel=1e-12)
    module(uniform([0.1]), dt=0.3)
    darker = 0.1 + (brighter - 0.1) * math.exp(-to_dark * 0.3)
    assert module.adapted_luminance.item() == pytest.approx(darker, rel=1e-12)


def test_adapt_luminance_formula():
    adapted, metered = torch.tensor([1.0, 2.0], dtype=torch.float64), torch.tensor([3.0, 0.5], dtype=torch.float64)
    new = adapt_luminance(adapted, metered, dt=0.7, speed=torch.tensor([0.5, 4.0], dtype=torch.float64))
    expected = adapted + (metered - adapted) * (1 - torch.exp(-0.7 * torch.tensor([0.5, 4.0], dtype=torch.float64)))
    torch.testing.assert_close(new, expected, rtol=1e-14, atol=0)


@pytest.mark.parametrize("metering", ["mean", "log"])
def test_uniform_scene_settles_on_middle_grey(metering, device):
    module = tg.AutoExposure(middle_grey=0.18, metering=metering)
    module(uniform([0.02], device=device))
    scene = uniform([7.0], device=device)
    out = module(scene, dt=60.0)
    torch.testing.assert_close(lum(out), torch.full((1, 8, 8), 0.18, dtype=torch.float64, device=device), rtol=1e-9, atol=0)


def test_per_sample_state_and_parameters_in_a_batch(device):
    start, target = [0.2, 1.0, 5.0], [3.0, 0.1, 5.0]
    speed = torch.tensor([0.5, 1.0, 2.0], dtype=torch.float64, device=device)
    middle_grey = torch.tensor([0.1, 0.18, 0.3], dtype=torch.float64, device=device)
    module = tg.AutoExposure(middle_grey=middle_grey, speed=speed, metering="mean")
    module(uniform(start, device=device))
    out = module(uniform(target, device=device), dt=0.4)
    start, target = (torch.tensor(v, dtype=torch.float64, device=device) for v in (start, target))
    expected = target + (start - target) * torch.exp(-0.4 * speed)
    torch.testing.assert_close(module.adapted_luminance, expected, rtol=1e-12, atol=0)
    expected_lum = target * middle_grey / expected
    torch.testing.assert_close(lum(out)[:, 0, 0], expected_lum, rtol=1e-12, atol=0)


def test_batch_size_change_mid_sequence_is_an_error():
    module = tg.AutoExposure()
    module(uniform([0.5, 1.0]))
    with pytest.raises(ValueError, match="reset"):
        module(uniform([0.5]), dt=0.1)
    module(uniform([0.5]))  # a still (dt=None) has no history to mismatch
    module.reset()
    module(uniform([1.0, 2.0, 3.0]), dt=0.1)
    assert module.adapted_luminance.shape == (3,)


def test_zero_state_means_no_history():
    image = torch.rand(2, 3, 6, 6) + 0.2
    fresh = auto_exposure(image, None, 0.5)
    zeros = auto_exposure(image, torch.zeros(2), 0.5)
    for a, b in zip(fresh, zeros):
        torch.testing.assert_close(a, b)


@pytest.mark.parametrize("dt", [math.nan, math.inf, -1.0, 1e6])
@pytest.mark.parametrize("speed", [0.0, 1.5])
def test_a_step_that_restarts_the_sequence_gives_the_first_frames_gradients(dt, speed):
    """A tensor step is not read: outside [0, 65504] it starts the sequence again, in values and in gradients (the
    branch not taken once carried a NaN step into the image's gradient and a learnable speed's)."""
    image = torch.rand(2, 3, 6, 6, dtype=torch.float64) + 0.2

    def gradients(state, step):
        stage = tg.AutoExposure(speed=torch.nn.Parameter(torch.tensor(speed, dtype=torch.float64)))
        x = image.clone().requires_grad_()
        exposed, adapted = stage.frame(x, state, step)  # a stage's frame does not read a tensor step
        (exposed.sum() + adapted.sum()).backward()
        return exposed, x.grad, stage.speed.grad

    restarted = gradients(torch.tensor([0.3, 2.0], dtype=torch.float64), torch.tensor(dt, dtype=torch.float64))
    fresh = gradients(None, 0.0)
    for got, want in zip(restarted[:2], fresh[:2]):
        torch.testing.assert_close(got, want)
    assert restarted[2] is None or restarted[2] == 0  # the speed moved nothing


# ---------------------------------------------------------------- operators


def test_reinhard_operator_matches_eq4():
    image = torch.rand(2, 3, 5, 7, dtype=torch.float64) * 30 + 0.01
    adapted = torch.tensor([0.4, 2.5], dtype=torch.float64).reshape(2, 1, 1, 1)
    middle_grey, white = 0.18, 16.0
    L = lum(image).unsqueeze(1)
    scaled = L * middle_grey / adapted
    compressed = scaled * (1 + scaled / white**2) / (1 + scaled)
    out = exposure_operator(image, adapted, middle_grey, white, "reinhard")
    torch.testing.assert_close(out, image * compressed / L, rtol=1e-12, atol=0)


def test_reinhard_maps_max_luminance_to_one():
    adapted, middle_grey, white = 0.7, 0.18, 16.0
    scene = uniform([white * adapted / middle_grey], size=(1, 1))
    out = exposure_operator(scene, torch.tensor(adapted, dtype=torch.float64), middle_grey, white, "reinhard")
    assert lum(out).item() == pytest.approx(1.0, rel=1e-12)


def test_reinhard_module_maps_a_settled_uniform_scene_to_compressed_middle_grey():
    middle_grey, white = 0.18, 16.0
    module = tg.AutoExposure(middle_grey=middle_grey, max_luminance=white, operator="reinhard")
    out = module(uniform([3.0]))
    expected = middle_grey * (1 + middle_grey / white**2) / (1 + middle_grey)
    torch.testing.assert_close(lum(out), torch.full((1, 8, 8), expected, dtype=torch.float64), rtol=1e-9, atol=0)


def test_exposure_operator_keeps_chromaticity_and_scales_linearly():
    image = torch.rand(1, 3, 4, 4, dtype=torch.float64) * 100
    out, adapted = auto_exposure(image, middle_grey=0.25)
    torch.testing.assert_close(out, image * 0.25 / adapted.reshape(1, 1, 1, 1), rtol=1e-12, atol=0)


# ---------------------------------------------------------------- robustness and gradients

EXTREMES = [0.0, 1e-8, 0.18, 60.0, 65504.0, 1e30, float("nan"), float("inf"), -float("inf")]


@pytest.mark.parametrize("operator", ["exposure", "reinhard"])
def test_extremes_give_finite_outputs_and_gradients(operator):
    image = torch.full((1, 3, 3, 3), 0.5)
    image.view(3, 9)[:, :] = torch.tensor(EXTREMES)
    image.requires_grad_(True)
    middle_grey = torch.tensor(0.18, requires_grad=True)
    module = tg.AutoExposure(middle_grey=middle_grey, operator=operator)
    module(image.detach())
    out = module(image, dt=0.1)
    assert torch.isfinite(out).all()
    out.sum().backward()
    assert torch.isfinite(image.grad).all() and torch.isfinite(middle_grey.grad)


def test_a_nan_pixel_does_not_spread():
    image = torch.rand(1, 3, 8, 8) + 0.1
    bad = image.clone()
    bad[0, :, 2, 5] = float("nan")
    clean = image.clone()
    clean[0, :, 2, 5] = 0.0
    out_bad, out_clean = tg.AutoExposure()(bad), tg.AutoExposure()(clean)
    torch.testing.assert_close(out_bad, out_clean)


@pytest.mark.parametrize("operator", ["exposure", "reinhard"])
def test_all_black_frame(operator):
    image = torch.zeros(2, 3, 5, 4, requires_grad=True)
    module = tg.AutoExposure(operator=operator, min_luminance=1e-3)
    out = module(image)
    assert torch.equal(out, torch.zeros_like(out))
    torch.testing.assert_close(module.adapted_luminance, torch.full((2,), 1e-3))
    out.sum().backward()
    assert torch.isfinite(image.grad).all()


@pytest.mark.parametrize("operator", ["exposure", "reinhard"])
@pytest.mark.parametrize("history", [False, True])
def test_gradcheck_image_and_middle_grey(operator, history):
    image = (torch.rand(2, 3, 4, 5, dtype=torch.float64) * 2 + 0.1).requires_grad_(True)
    middle_grey = torch.tensor([0.18, 0.3], dtype=torch.float64, requires_grad=True)
    adapted = torch.tensor([0.5, 1.5], dtype=torch.float64) if history else None

    def run(image, middle_grey):
        return auto_exposure(image, adapted, 0.3, middle_grey=middle_grey, max_luminance=4.0, operator=operator)

    assert torch.autograd.gradcheck(run, (image, middle_grey))


def test_learnable_middle_grey_is_a_module_parameter():
    middle_grey = torch.nn.Parameter(torch.tensor(0.18))
    module = tg.AutoExposure(middle_grey=middle_grey)
    assert any(p is middle_grey for p in module.parameters())
    module(torch.rand(1, 3, 4, 4)).sum().backward()
    assert middle_grey.grad is not None and middle_grey.grad > 0


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_low_precision_inputs_return_their_dtype(dtype):
    image = torch.rand(2, 3, 6, 6) * 10
    image[0, :, 0, 0] = 65504.0
    reference = tg.AutoExposure()(image)
    out = tg.AutoExposure()(image.to(dtype))
    assert out.dtype == dtype and torch.isfinite(out).all()
    torch.testing.assert_close(out.float(), reference, rtol=2e-2, atol=1e-3)


# ---------------------------------------------------------------- validation and configuration


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(middle_grey=0.0), "middle_grey"),
        (dict(middle_grey=float("nan")), "middle_grey"),
        (dict(max_luminance=-1.0), "max_luminance"),
        (dict(speed=-0.1), "speed"),
        (dict(speed_to_dark=-1.0), "speed_to_dark"),
        (dict(min_luminance=0.0), "min_luminance"),
        (dict(min_luminance=2.0, max_adapted=1.0), "min_luminance"),
        (dict(metering="median"), "metering"),
        (dict(operator="aces"), "operator"),
    ],
)
def test_bad_parameters_name_themselves(kwargs, name):
    with pytest.raises(ValueError, match=name):
        tg.AutoExposure(**kwargs)


def test_bad_inputs_raise_clear_errors():
    module = tg.AutoExposure()
    with pytest.raises(ValueError, match="dt"):
        module(torch.rand(1, 3, 4, 4), dt=-0.1)
    with pytest.raises(TypeError, match="floating-point"):
        module(torch.ones(1, 3, 4, 4, dtype=torch.uint8))
    with pytest.raises(ValueError, match="adapted"):
        auto_exposure(torch.rand(2, 3, 4, 4), torch.ones(3), 0.1)
    with pytest.raises(ValueError, match="middle_grey"):
        tg.AutoExposure(middle_grey=torch.tensor([0.18, 0.2]))(torch.rand(3, 3, 4, 4))


def test_config_round_trip():
    module = tg.AutoExposure(middle_grey=0.2, speed=torch.tensor([1.0, 2.0]), speed_to_light=3.0, min_luminance=0.3, max_adapted=1.0)
    config = module.to_config()
    assert config["speed"] == [1.0, 2.0] and config["max_adapted"] == 1.0 and config["operator"] == "exposure"
    assert tg.AutoExposure(**config).to_config() == config


def test_frame_is_forward_without_state():
    module = tg.AutoExposure(speed=2.0, metering="mean")
    module(torch.rand(2, 3, 8, 8) * 4)
    state = module.adapted_luminance.clone()
    image = torch.rand(2, 3, 8, 8)
    exposed, adapted = module.frame(image, state, 0.1)
    assert torch.equal(module.adapted_luminance, state)
    torch.testing.assert_close(module(image, dt=0.1), exposed)
    torch.testing.assert_close(module.adapted_luminance, adapted)


def test_learnable_control_moved_out_of_range_raises_at_forward():
    module = tg.AutoExposure(middle_grey=torch.nn.Parameter(torch.tensor(0.18)))
    with torch.no_grad():
        module.middle_grey.fill_(-1.0)
    with pytest.raises(ValueError, match="middle_grey"):
        module(torch.rand(1, 3, 4, 4))


# ---------------------------------------------------------------- ONNX


class _Functional(torch.nn.Module):
    def forward(self, image, adapted, dt):
        return auto_exposure(image, adapted, dt, middle_grey=0.18, speed=1.5, operator="reinhard")


def test_onnxruntime_matches_the_functional_form_at_several_shapes(tmp_path):
    ort = pytest.importorskip("onnxruntime")
    path = tmp_path / "auto_exposure.onnx"
    batch, height, width = (torch.export.Dim(n) for n in ("batch", "height", "width"))
    example = (torch.rand(2, 3, 40, 30) * 4, torch.tensor([0.5, 0.0]), torch.tensor(0.1))
    torch.onnx.export(
        _Functional().eval(), example, str(path), dynamo=True, opset_version=18,
        input_names=["image", "adapted", "dt"], output_names=["exposed", "new_adapted"],
        dynamic_shapes={"image": {0: batch, 2: height, 3: width}, "adapted": {0: batch}, "dt": {}},
    )
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    for shape in [(2, 3, 40, 30), (3, 3, 97, 131), (1, 3, 7, 5)]:
        image, adapted, dt = torch.rand(shape) * 8, torch.rand(shape[0]) + 0.1, torch.tensor(0.25)
        adapted[0] = 0.0  # one sample starting a sequence
        exposed, new = session.run(None, {"image": image.numpy(), "adapted": adapted.numpy(), "dt": dt.numpy()})
        expected_exposed, expected_new = _Functional()(image, adapted, dt)
        np.testing.assert_allclose(new, expected_new.numpy(), rtol=1e-5)
        np.testing.assert_allclose(exposed, expected_exposed.numpy(), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("state", [math.nan, math.inf, -math.inf, 1e-30, 1e30])
@pytest.mark.parametrize("operator", ["exposure", "reinhard"])
def test_a_state_that_is_not_a_bounded_luminance_gives_a_finite_frame_and_state(state, operator):
    """NaN, infinite or out-of-bounds states: the frame has no NaN and the state lands in [min_luminance, max_adapted]."""
    image = torch.rand(1, 3, 16, 16) * 4
    image[0, :, 0, 0] = torch.tensor([0.0, math.nan, math.inf])
    for dt in (0.0, 0.5, 65504.0):
        exposed, new = auto_exposure(image, torch.tensor([state]), torch.tensor(dt), operator=operator)
        assert not exposed.isnan().any() and exposed.abs().max() <= 65504.0
        assert MIN_LUMINANCE <= new.item() <= MAX_ADAPTED


def test_exported_look_restarts_from_a_nan_or_infinite_state_or_step(tmp_path):
    """The graph's inputs are unchecked: a NaN step or an infinite state meters afresh instead of a black frame."""
    pytest.importorskip("onnxruntime")
    stage = tg.AutoExposure(speed=1.5)
    runner = tg.onnx.session(tg.onnx.export(stage, tmp_path / "exposure.onnx"))
    image = torch.rand(1, 3, 24, 32) * 4
    image[0, :, 0, 0] = torch.tensor([0.0, math.nan, math.inf])
    fresh = runner.run(None, tg.onnx.feeds(runner, stage, (image, torch.zeros(1), torch.tensor(0.5))))
    for state, dt in [(math.inf, 0.5), (0.3, math.nan), (math.nan, math.inf), (-math.inf, 0.5)]:
        exposed, new = runner.run(None, tg.onnx.feeds(runner, stage, (image, torch.tensor([state]), torch.tensor(dt))))
        assert np.isfinite(exposed).all()
        np.testing.assert_array_equal(new, fresh[1])


EXTREME_REINHARD = {
    "fixed at the bounds": dict(operator="reinhard", fixed_exposure=32.0, compensation=32.0, middle_grey=100.0, max_luminance=0.01),
    "metered, darkest limit": dict(operator="reinhard", min_luminance=1e-6, middle_grey=100.0, compensation=32.0, max_luminance=0.01),
}


@pytest.mark.parametrize("controls", list(EXTREME_REINHARD))
def test_the_reinhard_operator_stays_finite_at_the_controls_bounds_alone_and_in_a_look(controls):
    """A gain of 2^64 with a white of 0.01: the product of the operator's two gains once overflowed, and a black channel
    times infinity is NaN (which the next stage of a look, trusting the exposed frame, would not remove)."""
    image = torch.zeros(1, 3, 8, 8)
    image[0, 0, 4, 4] = 65504.0
    image[0, :, 2, 2] = 1e-40
    with torch.no_grad():
        exposed = tg.AutoExposure(**EXTREME_REINHARD[controls])(image)
        looked = tg.PostFX(exposure=EXTREME_REINHARD[controls], grade={"contrast": 10.0}, tonemap="aces")(image)
    assert torch.isfinite(exposed).all() and exposed.abs().max() <= 65504.0
    assert torch.isfinite(looked).all()
