"""Engine-parity grading tools against independent references: Unity's lift/gamma/gain and curves
(URP LutBuilderHdr, re-implemented per pixel in float64), Fritsch–Carlson splines (a plain-Python
transcription of the 1980 algorithm), OpenColorIO's GradingPrimaryTransform, and TPDF dither statistics."""

import colorsys
import inspect
import math

import numpy as np
import PyOpenColorIO as OCIO
import pytest
import torch
from hypothesis import given, settings, strategies as st

import torchgrade as tg
from torchgrade import functional as F

from reference.pixels import LUM709, pixels, random_rgb, rows
from reference.tonemap import AP0_2_AP1, AP1_Y, SRGB_2_AP0
from reference.grade import sample_pixels, srgb_decode, unity_grade_pixel
from reference.onnx import display_error, hdr, SHAPES, STEP_TOLERANCE, TOLERANCE

# ---------------------------------------------------------------- references


def fritsch_carlson(points, periodic=False):
    """Knots, values and tangents of Fritsch & Carlson's monotone interpolant (SIAM J. Numer. Anal. 1980), step by step."""
    xs, ys = [float(p[0]) for p in points], [float(p[1]) for p in points]
    if periodic:
        xs, ys = xs + [xs[0] + 1.0], ys + [ys[0]]
    n = len(xs)
    d = [(ys[k + 1] - ys[k]) / (xs[k + 1] - xs[k]) for k in range(n - 1)]
    m = []
    for k in range(n):
        left = d[k - 1] if k > 0 else (d[-1] if periodic else d[0])
        right = d[k] if k < n - 1 else (d[0] if periodic else d[-1])
        m.append((left + right) / 2 if left * right > 0 else 0.0)
    for k in range(n - 1):
        if d[k] == 0:
            continue
        alpha, beta = m[k] / d[k], m[k + 1] / d[k]
        if alpha**2 + beta**2 > 9:
            tau = 3 / math.sqrt(alpha**2 + beta**2)
            m[k], m[k + 1] = tau * alpha * d[k], tau * beta * d[k]
            if periodic and k + 1 == n - 1:
                m[0] = m[k + 1]  # the last knot is the first one, a turn later
    return xs, ys, m


def spline_at(points, t, periodic=False):
    xs, ys, m = fritsch_carlson(points, periodic)
    t = xs[0] + (t - xs[0]) % 1.0 if periodic else min(max(t, xs[0]), xs[-1])
    k = max(i for i in range(len(xs) - 1) if xs[i] <= t)
    h = xs[k + 1] - xs[k]
    s = (t - xs[k]) / h
    return (2 * s**3 - 3 * s**2 + 1) * ys[k] + (s**3 - 2 * s**2 + s) * h * m[k] + (-2 * s**3 + 3 * s**2) * ys[k + 1] + (s**3 - s**2) * h * m[k + 1]


LUMA = LUM709 / LUM709.sum()
"""Unity's Luminance weights normalised to sum 1 (they sum to 1.0000001), as torchgrade prepares trackballs."""


def prepare_lift_gamma_gain(lift, gamma, gain):
    """Unity ColorUtils.PrepareLiftGammaGain."""
    def decode(v):
        return np.array([srgb_decode(c) for c in v[:3]])
    lf = decode(lift) * 0.15
    lf = lf - lf @ LUMA + lift[3]
    g = decode(gamma) * 0.8
    inverse_gamma = 1 / np.maximum(g - g @ LUMA + gamma[3] + 1, 1e-3)
    k = decode(gain) * 0.8
    return lf, inverse_gamma, k - k @ LUMA + gain[3] + 1


TAIL_DEFAULTS = dict(lift=(1, 1, 1, 0), gamma=(1, 1, 1, 0), gain=(1, 1, 1, 0), hue_shift=0.0, saturation=0.0)
CURVE_NAMES = ("hue_vs_hue", "hue_vs_sat", "sat_vs_sat", "lum_vs_sat", "curve_master", "curve_red", "curve_green", "curve_blue")


def unity_tail_pixel(c, weights=LUM709, **controls):
    """URP LutBuilderHdr after shadows/midtones/highlights: lift/gamma/gain, HSV curves, hue shift, saturation, YRGB curves."""
    p = {**TAIL_DEFAULTS, **{name: None for name in CURVE_NAMES}, **controls}
    c = np.array(c, dtype=np.float64)
    if any(p[name] != TAIL_DEFAULTS[name] for name in ("lift", "gamma", "gain")):
        lift, inverse_gamma, gain = prepare_lift_gamma_gain(p["lift"], p["gamma"], p["gain"])
        c = c * gain + lift
        c = np.maximum(np.sign(c) * np.abs(c) ** inverse_gamma, 0)
    h, s, v = colorsys.rgb_to_hsv(*c)
    sat_mult = 1.0
    for name, axis, periodic in (("hue_vs_sat", h, True), ("sat_vs_sat", s, False), ("lum_vs_sat", c @ weights, False)):
        if p[name] is not None:
            sat_mult *= spline_at(p[name], axis, periodic) * 2
    hue = h + p["hue_shift"] / 360
    if p["hue_vs_hue"] is not None:
        hue += spline_at(p["hue_vs_hue"], hue, periodic=True) - 0.5
    c = np.array(colorsys.hsv_to_rgb(hue % 1.0, s, v))
    y = c @ weights
    c = y + (1 + p["saturation"] / 100) * sat_mult * (c - y)
    if any(p[name] is not None for name in CURVE_NAMES[4:]):
        t = c / (1 + max(c))
        if p["curve_master"] is not None:
            t = np.array([spline_at(p["curve_master"], v) for v in t])
        t = np.array([v if curve is None else spline_at(curve, v) for v, curve in zip(t, [p[n] for n in CURVE_NAMES[5:]])])
        c = np.maximum(t / (1 - max(t)), 0)
    return np.maximum(c, 0)


HUE_CURVE = ((0.0, 0.5), (0.2, 0.62), (0.45, 0.5), (0.7, 0.35), (0.9, 0.5))
SAT_CURVE = ((0.0, 0.3), (0.4, 0.55), (1.0, 0.7))
MASTER = ((0.0, 0.0), (0.25, 0.18), (0.6, 0.7), (1.0, 1.0))
TAIL_LOOKS = {
    "lift_gamma_gain": dict(lift=(0.9, 1.0, 0.8, 0.02), gamma=(1.0, 0.85, 0.9, -0.1), gain=(0.8, 1.0, 1.0, 0.2)),
    "crushing_lift": dict(lift=(1.0, 1.0, 1.0, -0.3)),
    "hue_vs_hue": dict(hue_vs_hue=HUE_CURVE, hue_shift=25.0),
    "sat_curves": dict(hue_vs_sat=HUE_CURVE, sat_vs_sat=SAT_CURVE, lum_vs_sat=((0.0, 0.5), (0.5, 0.8), (1.0, 0.4)), saturation=15.0),
    "yrgb": dict(curve_master=MASTER, curve_red=((0.0, 0.05), (0.5, 0.55), (1.0, 0.95)), curve_blue=((0.1, 0.0), (0.95, 0.97))),
    "everything": dict(
        lift=(0.95, 1.0, 1.0, 0.01), gamma=(1.0, 1.0, 0.9, 0.05), gain=(1.0, 0.95, 1.0, 0.1), hue_shift=-30.0, saturation=-20.0,
        hue_vs_hue=HUE_CURVE, hue_vs_sat=HUE_CURVE, sat_vs_sat=SAT_CURVE, curve_master=MASTER, curve_green=((0.0, 0.0), (1.0, 0.9)),
    ),
}
EARLY = dict(post_exposure=0.3, temperature=15, contrast=20, split_shadows=(0.4, 0.5, 0.6), midtones=(1.05, 1.0, 0.95))


# ---------------------------------------------------------------- curves


STEEP = ((0.0, 0.0), (0.1, 0.9), (0.2, 1.0), (0.9, 1.0))
TWO_POINTS = ((0.3, 0.2), (0.5, 0.9))


@pytest.mark.parametrize(
    "points, periodic",
    [(HUE_CURVE, True), (STEEP, True), (TWO_POINTS, True), (HUE_CURVE, False), (SAT_CURVE, False), (MASTER, False), (STEEP, False), (TWO_POINTS, False)],
)
def test_spline_matches_fritsch_carlson_reference(points, periodic):
    t = np.concatenate((np.linspace(-0.3, 1.3, 161), [p[0] for p in points]))
    ours = F.evaluate_curve(points, torch.from_numpy(t), periodic=periodic).numpy()
    np.testing.assert_allclose(ours, [spline_at(points, v, periodic) for v in t], rtol=0, atol=1e-12)


monotone_points = st.lists(st.tuples(st.floats(0.01, 1.0), st.floats(0.0, 1.0)), min_size=2, max_size=8).map(
    lambda steps: tuple(zip(np.cumsum([s[0] for s in steps]) / sum(s[0] for s in steps) - steps[0][0] / sum(s[0] for s in steps),
                            np.sort([s[1] for s in steps])))
)


@settings(max_examples=40, deadline=None)
@given(monotone_points)
def test_spline_through_monotone_points_is_monotone_without_overshoot(points):
    t = torch.linspace(-0.1, 1.1, 2001, dtype=torch.float64)
    values = F.evaluate_curve(points, t)
    assert (values.diff() >= -1e-12).all()
    ys = [p[1] for p in points]
    assert values.min() >= min(ys) - 1e-12 and values.max() <= max(ys) + 1e-12
    knots = F.evaluate_curve(points, torch.tensor([p[0] for p in points], dtype=torch.float64))
    np.testing.assert_allclose(knots.numpy(), ys, atol=1e-12)


def test_collinear_points_give_the_line_and_periodic_curves_close():
    t = torch.linspace(0.0, 1.0, 101, dtype=torch.float64)
    torch.testing.assert_close(F.evaluate_curve(((0.0, 0.0), (0.3, 0.3), (1.0, 1.0)), t), t, atol=1e-15, rtol=0)
    ends = F.evaluate_curve(HUE_CURVE, torch.tensor([-1e-9, 1e-9, 1.0 - 1e-9], dtype=torch.float64), periodic=True)
    assert float((ends - ends[1]).abs().max()) < 1e-8


GENERIC_HUE_Y = (0.45, 0.62, 0.5, 0.35, 0.55)
"""y values for HUE_CURVE's x without a flat stretch or extremum at a knot (where the tangent rule has a kink)."""


def test_curve_gradcheck_in_values_and_control_point_y():
    xs = torch.tensor([p[0] for p in HUE_CURVE], dtype=torch.float64)
    ys = torch.tensor(GENERIC_HUE_Y, dtype=torch.float64, requires_grad=True)
    t = (torch.rand(40, dtype=torch.float64) * 1.4 - 0.2).requires_grad_()
    for periodic in (False, True):
        assert torch.autograd.gradcheck(lambda t, y, periodic=periodic: F.evaluate_curve(torch.stack((xs, y), 1), t, periodic), (t, ys))


# ---------------------------------------------------------------- ColorGrade: lift/gamma/gain and curves


@pytest.mark.parametrize("look", sorted(TAIL_LOOKS))
def test_new_controls_match_unity_reference(look):
    rgb = sample_pixels()
    ours = rows(tg.ColorGrade(**TAIL_LOOKS[look])(pixels(rgb)))
    expected = [unity_tail_pixel(np.maximum(c, 0), **TAIL_LOOKS[look]) for c in rgb]
    np.testing.assert_allclose(ours, expected, rtol=1e-9, atol=1e-9)


def test_new_controls_after_the_existing_steps_match_unity_reference():
    rgb = sample_pixels()
    ours = rows(tg.ColorGrade(**EARLY, **TAIL_LOOKS["everything"])(pixels(rgb)))
    expected = [unity_tail_pixel(unity_grade_pixel(c, **EARLY), **TAIL_LOOKS["everything"]) for c in rgb]
    np.testing.assert_allclose(ours, expected, rtol=1e-9, atol=1e-9)


def test_new_controls_in_aces_match_unity_reference():
    rgb = sample_pixels()
    ours = rows(tg.ColorGrade(aces=True, **TAIL_LOOKS["everything"])(pixels(rgb)))
    to_ap1, from_ap1 = AP0_2_AP1 @ SRGB_2_AP0, np.linalg.inv(SRGB_2_AP0)
    expected = [from_ap1 @ np.maximum(np.linalg.inv(AP0_2_AP1) @ unity_tail_pixel(np.maximum(to_ap1 @ c, 0), AP1_Y, **TAIL_LOOKS["everything"]), 0) for c in rgb]
    np.testing.assert_allclose(ours, expected, rtol=1e-9, atol=1e-9)


def test_curves_reaching_one_stay_finite():
    """A curve that maps to 1 would divide by 0 in FastTonemapInvert; the divisor is bounded, so outputs stay <= 65505."""
    image = torch.tensor([0.0, 0.5, 3.0, 1e4]).reshape(1, 1, 1, 4).expand(1, 3, 1, 4).contiguous()
    out = tg.ColorGrade(curve_master=((0.0, 0.0), (0.5, 1.0)))(image)
    assert torch.isfinite(out).all() and out.max() <= 65505 and out[0, 0, 0, 0] == 0


def test_identity_trackballs_are_exact_when_evaluated():
    """A grey trackball changes nothing even when the step is computed (learnable controls, ONNX graph inputs)."""
    image = hdr((1, 3, 8, 8))
    identity = torch.tensor([1.0, 1.0, 1.0, 0.0])
    assert torch.equal(F.lift_gamma_gain(image, identity, identity, identity), image)
    lift, inverse_gamma, gain = F.lift_gamma_gain_coefficients((0.5, 0.5, 0.5, 0.1), identity, (0.7, 0.7, 0.7, 0.0), image)
    assert torch.equal(lift, torch.full_like(lift, 0.1)) and torch.equal(inverse_gamma, torch.ones_like(lift)) and torch.equal(gain, torch.ones_like(gain))


def test_lift_gamma_gain_mirrors_negative_values():
    c = pixels([[-0.2, 0.5, -1.5], [0.0, 2.0, 0.1]])
    lift, gamma, gain = (0.9, 1.0, 0.8, 0.05), (0.7, 1.0, 1.0, 0.2), (1.0, 1.0, 0.9, -0.1)
    lf, inverse_gamma, k = prepare_lift_gamma_gain(lift, gamma, gain)
    expected = [np.sign(v * k + lf) * np.abs(v * k + lf) ** inverse_gamma for v in rows(c)]
    np.testing.assert_allclose(rows(F.lift_gamma_gain(c, lift, gamma, gain)), expected, rtol=1e-12, atol=1e-12)


IDENTITY_SETTINGS = dict(
    lift=(1, 1, 1, 0), gamma=(1.0, 1.0, 1.0, 0.0), gain=[1.0, 1.0, 1.0, 0.0], hue_vs_hue=((0.0, 0.5), (0.6, 0.5)),
    hue_vs_sat=None, sat_vs_sat=((0.0, 0.5), (1.0, 0.5)), lum_vs_sat=(), curve_master=((0.0, 0.0), (0.5, 0.5), (1.0, 1.0)), curve_red=None,
)


def test_identity_settings_return_the_input_itself():
    image = torch.rand(2, 3, 5, 6)
    for aces in (False, True):
        grade = tg.ColorGrade(aces=aces, **IDENTITY_SETTINGS)
        assert grade.is_identity and grade(image) is image and grade.to_config() == ({"aces": True} if aces else {})


def test_a_tensor_control_at_identity_is_computed_and_changes_nothing():
    """A tensor's value is not read to skip its step (on a GPU each read waits for the device, and a compiler's graph
    holds no value): the trackball is applied, and gives the image back to float rounding."""
    image = torch.rand(2, 3, 5, 6)
    grade = tg.ColorGrade(gain=torch.tensor([1.0, 1.0, 1.0, 0.0]))
    assert not grade.is_identity
    torch.testing.assert_close(grade(image), image)


def test_curves_and_trackballs_in_configs_round_trip():
    grade = tg.ColorGrade(**TAIL_LOOKS["everything"])
    look = tg.PostFX.from_config({"grade": grade.to_config()})
    image = torch.rand(1, 3, 4, 4, dtype=torch.float64) * 3
    torch.testing.assert_close(look(image), grade(image))


def test_per_sample_trackballs_equal_separate_runs():
    image = torch.rand(2, 3, 4, 5, dtype=torch.float64) * 3
    lift = torch.tensor([[1.0, 0.9, 0.8, 0.05], [0.8, 1.0, 1.0, -0.05]], dtype=torch.float64)
    gain = torch.tensor([[1.0, 1.0, 1.0, 0.3], [1.0, 0.9, 1.0, 0.0]], dtype=torch.float64)
    batched = tg.ColorGrade(lift=lift, gain=gain, curve_master=MASTER)(image)
    for i in range(2):
        single = tg.ColorGrade(lift=lift[i].tolist(), gain=gain[i].tolist(), curve_master=MASTER)(image[i : i + 1])
        torch.testing.assert_close(batched[i : i + 1], single)


def test_learnable_curve_y_and_trackball_get_gradients():
    curve = torch.nn.Parameter(torch.tensor(MASTER, dtype=torch.float32))
    grade = tg.ColorGrade(curve_master=curve, gamma=torch.nn.Parameter(torch.tensor([1.0, 1.0, 1.0, 0.0])))
    assert not grade.is_identity
    grade(torch.rand(2, 3, 4, 4) * 4).sum().backward()
    assert torch.isfinite(curve.grad).all() and (curve.grad[:, 1] != 0).any() and (curve.grad[:, 0] == 0).all()
    assert torch.isfinite(grade.gamma.grad).all()


CURVE_X = torch.tensor([p[0] for p in MASTER], dtype=torch.float64)
HUE_X = torch.tensor([p[0] for p in HUE_CURVE], dtype=torch.float64)
NEW_OPS = {
    "lift_gamma_gain": (F.lift_gamma_gain, ((0.9, 1.0, 0.8, 0.05), (1.0, 0.8, 0.9, 0.1), (0.9, 1.0, 1.0, 0.2))),
    "hue_vs_hue": (lambda x, d, y: F.hue_shift(x, d, torch.stack((HUE_X, y), 1)), (20.0, GENERIC_HUE_Y)),
    "saturation_curves": (lambda x, y: F.saturation_curves(x, torch.stack((HUE_X, y), 1), SAT_CURVE, SAT_CURVE), (GENERIC_HUE_Y,)),
    "yrgb_curves": (lambda x, y: F.yrgb_curves(x, torch.stack((CURVE_X, y), 1), None, SAT_CURVE), ([p[1] for p in MASTER],)),
    "offset_exposure": (F.offset_exposure, ((0.01, -0.02, 0.03), (0.5, 0.0, -0.3))),
    "linear_contrast": (F.linear_contrast, ((1.3, 0.9, 1.1), -0.5)),
    "primary_log_contrast": (F.primary_log_contrast, ((1.3, 0.9, 1.1), 0.1)),
    "log_gamma": (F.log_gamma, ((1.3, 0.9, 1.1), 0.05, 0.95)),
    "primary_saturation": (F.primary_saturation, (1.4,)),
    "dither": (lambda x, a: F.dither(x, F.dither_pattern(8, torch.Generator().manual_seed(1), torch.float64), a), (2 / 255,)),
}


@pytest.mark.parametrize("name", sorted(NEW_OPS))
def test_gradcheck_image_and_parameters(name):
    op, params = NEW_OPS[name]
    image = (torch.rand(1, 3, 3, 3, dtype=torch.float64) * 0.8 + 0.1).requires_grad_()
    params = tuple(torch.tensor(p, dtype=torch.float64, requires_grad=True) for p in params)
    assert torch.autograd.gradcheck(op, (image,) + params)


def test_extremes_give_finite_outputs_and_gradients():
    from test_grade import extremes_image

    for aces in (False, True):
        image = extremes_image().requires_grad_()
        out = tg.ColorGrade(aces=aces, **TAIL_LOOKS["everything"])(image)
        out.sum().backward()
        assert torch.isfinite(out).all() and torch.isfinite(image.grad).all()


@pytest.mark.parametrize(
    "controls, message",
    [
        (dict(lift=(1, 1, 1)), r"lift must be of shape \(4,\) or \(B, 4\)"),
        (dict(gain=(1, 1, 1, 1.5)), r"gain must lie in \[-1.0, 1.0\]"),
        (dict(curve_master=((0.5, 0.2), (0.4, 0.6))), "curve_master x values must be strictly increasing"),
        (dict(hue_vs_hue=((0.0, 0.5), (1.0, 0.5))), r"hue_vs_hue x values must lie in \[0, 1\)"),
        (dict(sat_vs_sat=((0.0, 0.5), (1.0, 1.5))), "sat_vs_sat y"),
        (dict(curve_red=((0.5, 0.5),)), "curve_red must be at least two"),
    ],
)
def test_bad_new_controls_name_the_parameter(controls, message):
    with pytest.raises(ValueError, match=message):
        tg.ColorGrade(**controls)(torch.rand(1, 3, 2, 2))


# ---------------------------------------------------------------- PrimaryGrade against OpenColorIO

RGBM = OCIO.GradingRGBM
OCIO_STYLE = {"linear": OCIO.GRADING_LIN, "log": OCIO.GRADING_LOG}
PRIMARY_LOOKS = {
    "linear": [
        dict(offset=(0.01, -0.02, 0.03)),
        dict(exposure=(0.5, 0.0, -0.3)),
        dict(contrast=(1.3, 0.9, 1.1)),
        dict(contrast=(1.5, 1.5, 1.5), pivot=-0.5),
        dict(saturation=1.4),
        dict(offset=(0.01, -0.02, 0.03), exposure=(0.7, 0.2, -0.1), contrast=(1.3, 0.9, 1.1), pivot=0.4, saturation=0.6),
    ],
    "log": [
        dict(brightness=(10.0, 20.0, -30.0)),
        dict(contrast=(1.3, 0.8, 1.1), pivot=0.3),
        dict(gamma=(1.5, 0.8, 1.2), pivot_black=0.1, pivot_white=0.9),
        dict(brightness=(5.0, -5.0, 0.0), contrast=(1.2, 1.2, 1.1), gamma=(1.1, 0.9, 1.3), saturation=1.3),
    ],
}


def ocio_primary(style, rgb, **controls):
    primary = OCIO.GradingPrimary(OCIO_STYLE[style])
    for name in ("offset", "exposure", "brightness", "contrast", "gamma"):
        if name in controls:
            setattr(primary, name, RGBM(*controls[name], 1.0 if name in ("contrast", "gamma") else 0.0))
    for ours, theirs in (("saturation", "saturation"), ("pivot", "pivot"), ("pivot_black", "pivotBlack"), ("pivot_white", "pivotWhite")):
        if ours in controls:
            setattr(primary, theirs, controls[ours])
    transform = OCIO.GradingPrimaryTransform(primary, OCIO_STYLE[style], False)
    processor = OCIO.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor()
    return np.array([processor.applyRGB([float(v) for v in c]) for c in rgb])


@pytest.mark.parametrize("style, index", [(s, i) for s, looks in PRIMARY_LOOKS.items() for i in range(len(looks))])
def test_primary_grade_matches_opencolorio(style, index):
    controls = PRIMARY_LOOKS[style][index]
    rgb = random_rgb(200, high=1.0, seed=3) * 1.4 - 0.2 if style == "log" else random_rgb(200, high=1.0, seed=3) ** 2 * 20.0 - 0.5
    rgb[:3] = [[0.0, 0.0, 0.0], [0.18, 0.18, 0.18], [-0.3, 0.5, 1e-4]]
    ours = rows(tg.PrimaryGrade(style, **controls)(pixels(rgb)))
    # OpenColorIO computes in float32 with a fast pow approximation (relative error ~2e-5, and up
    # to 2e-6 absolute where a log-style gamma is applied near its black pivot).
    np.testing.assert_allclose(ours, ocio_primary(style, rgb, **controls), rtol=1e-4, atol=5e-6)


def test_primary_defaults_are_opencolorio_defaults_and_identity_returns_the_input():
    for style in ("linear", "log"):
        assert OCIO.GradingPrimary(OCIO_STYLE[style]).pivot == pytest.approx(tg.grading.primary.DEFAULT_PIVOT[style])
        image = torch.rand(2, 3, 4, 4)
        grade = tg.PrimaryGrade(style, contrast=(1.0, 1.0, 1.0), pivot=0.3)
        assert grade.is_identity and grade(image) is image


def test_primary_per_sample_and_bad_controls():
    image = torch.rand(2, 3, 4, 4, dtype=torch.float64)
    exposure = torch.tensor([[0.5, 0.0, 0.0], [0.0, -1.0, 0.2]], dtype=torch.float64)
    batched = tg.PrimaryGrade(exposure=exposure, saturation=torch.tensor([1.2, 0.8], dtype=torch.float64))(image)
    for i, s in enumerate((1.2, 0.8)):
        torch.testing.assert_close(batched[i : i + 1], tg.PrimaryGrade(exposure=exposure[i].tolist(), saturation=s)(image[i : i + 1]))
    with pytest.raises(ValueError, match="gamma is not a control of the linear style"):
        tg.PrimaryGrade(gamma=(1.2, 1.0, 1.0))
    with pytest.raises(ValueError, match="style must be one of"):
        tg.PrimaryGrade("video")
    with pytest.raises(ValueError, match=r"contrast must lie in \[0.0, 10.0\]"):
        tg.PrimaryGrade(contrast=(-1.0, 1.0, 1.0))


# ---------------------------------------------------------------- Dither


def test_dither_noise_is_triangular_within_one_code():
    noise = F.dither_pattern(256, torch.Generator().manual_seed(5), torch.float64) / 255
    a = 1 / 255
    assert noise.abs().max() <= a and abs(float(noise.mean())) < 0.01 * a
    assert float(noise.var()) == pytest.approx(a * a / 6, rel=0.02)
    histogram = torch.histc(noise * 255, bins=10, min=-1.0, max=1.0) / noise.numel()
    triangle = torch.tensor([(1 - abs(c)) * 0.2 for c in np.linspace(-0.9, 0.9, 10)], dtype=torch.float64)
    assert float((histogram - triangle).abs().max()) < 0.01


def test_dither_adds_the_tile_in_srgb_and_is_seeded(device):
    image = torch.rand(2, 3, 70, 90, dtype=torch.float64, device=device) * 0.9 + 0.05
    out = tg.Dither(amplitude=1 / 255, seed=3, size=16).to(device)(image)
    pattern = F.dither_pattern(16, torch.Generator().manual_seed(3), torch.float64).to(device)
    rows_, cols = torch.arange(70, device=device) % 16, torch.arange(90, device=device) % 16
    expected = tg.color.srgb_to_linear(tg.color.linear_to_srgb(image) + pattern[rows_][:, cols] / 255)
    torch.testing.assert_close(out, expected)
    torch.testing.assert_close(out, tg.Dither(seed=3, size=16)(image), rtol=0, atol=0)
    assert not torch.equal(out, tg.Dither(seed=4, size=16)(image))
    step = (tg.color.linear_to_srgb(out) - tg.color.linear_to_srgb(image)).abs().max()
    assert step <= 1 / 255 + 1e-12


def test_dither_is_off_by_default_and_identity_at_zero():
    image = torch.rand(1, 3, 4, 4)
    assert "dither" not in tg.PostFX(tonemap="neutral").stages()
    assert tg.Dither(amplitude=0.0)(image) is image
    assert "dither" not in tg.PostFX(tonemap="neutral", dither={"amplitude": 0.0}).stages()


def test_dither_removes_banding_on_a_smooth_ramp():
    """8-bit quantisation of a gentle ramp: undithered, each column is off by up to half a code; dithered,
    the mean over 64 rows lands on the unquantised value."""
    encoded = torch.linspace(0.3, 0.3 + 6 / 255, 240, dtype=torch.float64).expand(1, 3, 64, 240)
    linear = tg.color.srgb_to_linear(encoded)
    def quantise(x):
        return torch.round(tg.color.linear_to_srgb(x) * 255) / 255
    banded = (quantise(linear).mean(dim=-2) - encoded[..., 0, :]).abs() * 255
    dithered = (quantise(tg.Dither()(linear)).mean(dim=-2) - encoded[..., 0, :]).abs() * 255
    assert float(banded.mean()) > 0.2 and float(dithered.mean()) < 0.08 and float(dithered.max()) < 0.3


def test_primary_and_dither_stages_in_a_look():
    image = torch.rand(1, 3, 8, 8) * 4
    look = tg.PostFX(grade={"contrast": 10}, primary={"exposure": (0.2, 0.2, 0.2)}, tonemap="neutral", dither={"seed": 2})
    assert list(look.stages()) == ["grade", "primary", "tonemap", "dither"]
    expected = tg.Dither(seed=2)(tg.ToneMap("neutral")(tg.PrimaryGrade(exposure=(0.2, 0.2, 0.2))(tg.ColorGrade(contrast=10)(image))))
    torch.testing.assert_close(look(image), expected)
    torch.testing.assert_close(tg.PostFX.from_config(look.to_config())(image), expected)
    baked = look.to_lut(size=17)
    assert list(baked.stages()) == ["lut", "dither"]


def test_primary_and_dither_are_stages_checked_from_their_tables():
    assert [p for p in inspect.signature(tg.PrimaryGrade).parameters] == list(tg.PrimaryGrade.controls)
    grade = tg.PrimaryGrade(saturation=torch.nn.Parameter(torch.tensor(1.5)))
    with torch.no_grad():
        grade.saturation.fill_(20.0)
    with pytest.raises(ValueError, match=r"saturation must lie in \[0.0, 10.0\]"):
        grade(torch.rand(1, 3, 2, 2))
    layer = tg.Dither(seed=3, size=16)
    layer.seed = 4
    assert torch.equal(layer.pattern, tg.Dither(seed=4, size=16).pattern)
    assert tg.Dither.from_config(layer.to_config()).to_config() == layer.to_config() == {"amplitude": 1 / 255, "seed": 4, "size": 16}


# ---------------------------------------------------------------- ONNX


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("onnx_parity")


@pytest.mark.parametrize("aces", [False, True], ids=["linear", "aces"])
def test_onnx_grade_with_new_controls_matches(folder, aces):
    look = tg.PostFX(grade=tg.ColorGrade(aces=aces, **TAIL_LOOKS["everything"]), tonemap="neutral")
    path = tg.onnx.export(look, folder / f"grade_{aces}.onnx")
    for shape in SHAPES:
        assert tg.onnx.verify(look, path, hdr(shape)) <= TOLERANCE


def test_onnx_grade_inputs_keep_curves_baked_and_take_trackballs(folder):
    look = tg.PostFX(grade=TAIL_LOOKS["everything"], tonemap="neutral")
    path = tg.onnx.export(look, folder / "grade_inputs.onnx", grade_inputs=True)
    runner = tg.onnx.session(path)
    assert [i.name for i in runner.get_inputs()] == ["image", *tg.onnx.GRADE_INPUTS]
    assert runner.get_overridable_initializers() == []
    for shape in SHAPES:
        assert tg.onnx.verify(look, path, hdr(shape)) <= STEP_TOLERANCE
    lifts = torch.tensor([[1.0, 0.9, 0.8, 0.05], [0.8, 1.0, 1.0, -0.05]])
    image = hdr((2, 3, 9, 11))
    feeds = {k: v.numpy() for k, v in tg.onnx.grade_feeds(look.grade, 2).items()}
    output = runner.run(None, {"image": image.numpy(), **feeds, "lift": lifts.numpy()})[0]
    for i in range(2):
        expected = tg.PostFX(grade={**TAIL_LOOKS["everything"], "lift": lifts[i].tolist()}, tonemap="neutral")(image[i : i + 1])
        np.testing.assert_allclose(output[i : i + 1], expected.detach().numpy(), atol=STEP_TOLERANCE, rtol=0)


@pytest.mark.parametrize("style", ["linear", "log"])
def test_onnx_primary_grade_matches(folder, style):
    module = tg.PrimaryGrade(style, **PRIMARY_LOOKS[style][-1])
    path = tg.onnx.export(module, folder / f"primary_{style}.onnx")
    for shape in SHAPES:
        assert display_error(module, path, hdr(shape)) <= TOLERANCE


def test_onnx_dither_matches_at_every_shape(folder):
    look = tg.PostFX(tonemap="neutral", dither={"amplitude": 1 / 255, "seed": 7})
    path = tg.onnx.export(look, folder / "dither.onnx")
    for shape in SHAPES:
        assert tg.onnx.verify(look, path, hdr(shape)) <= TOLERANCE
