"""Every documented control range is a promise: values inside give finite outputs and gradients, values outside raise.

For each module, hypothesis draws every number, int, bool and choice control from the module's own
table (edges included), a small image from extreme finite pixels, and checks that the output and
the gradients with respect to the image and to every number control are finite. Values outside a
range, NaN and Inf raise ``ValueError`` naming the control at construction, on assignment and, for
an ``nn.Parameter`` an optimiser moved, at forward.
"""

from __future__ import annotations

import json
import math

import pytest
import torch
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st
from torch import nn

import torchgrade as tg
from torchgrade.bloom import BLOOM_MODES
from torchgrade.lut import identity_table
from torchgrade.lut.layer import entry_bound
from torchgrade.tonemap.registry import TONE_MAPPERS

# Controls that take plain numbers only (ACES 2.0 caches its tables per peak luminance).
PLAIN_NUMBERS = ("peak_luminance",)
# Extreme finite pixels: black, float32 denormals (the smallest, and 1e-40, whose square underflows) and its smallest
# normal, grey, Reinhard's 60, half's largest, negatives.
PIXELS = (0.0, 1e-45, 1e-40, 1e-38, 0.18, 1.0, 60.0, 65504.0, -1.0, -0.18, -65504.0)
SETTINGS = settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))


def images():
    """(1, 3, 4, 4) float32 images of extreme pixels."""
    return st.lists(st.sampled_from(PIXELS), min_size=48, max_size=48).map(lambda v: torch.tensor(v).reshape(1, 3, 4, 4))


def _number(low, high):
    return st.one_of(st.sampled_from((low, high)), st.floats(low, high, allow_nan=False))


def _shape(default) -> tuple:
    return tuple(torch.as_tensor(default if default is not None else 0.0, dtype=torch.float64).shape)


def control_values(table: dict, skip=()):
    """A strategy of ``{name: value}`` over ``table``: number controls as float32 leaf tensors that require grad."""
    strategies = {}
    for name, control in table.items():
        if name in skip:
            continue
        if control.kind == "number":
            low, high = control.range
            shape = _shape(control.default)
            count = math.prod(shape)
            values = st.lists(_number(low, high), min_size=count, max_size=count)
            if name in PLAIN_NUMBERS:
                strategies[name] = values.map(lambda v: v[0])
            else:
                strategies[name] = values.map(lambda v, shape=shape: torch.tensor(v, dtype=torch.float32).reshape(shape).requires_grad_())
        elif control.kind == "int":
            low, high = control.range
            strategies[name] = st.sampled_from(sorted({low, high, control.default}))
        elif control.kind == "bool":
            strategies[name] = st.booleans()
        elif control.kind == "choice":
            strategies[name] = st.sampled_from(tuple(control.range))
    return st.fixed_dictionaries(strategies)


def build(cls, *args, **controls):
    """The module, or a hypothesis rejection when the drawn controls break a rule between controls (zone order)."""
    try:
        return cls(*args, **controls)
    except ValueError as error:
        if "below" in str(error) or "exceed" in str(error):
            reject()
        raise


def assert_finite(module, image, controls, *args, **kwargs):
    image = image.clone().requires_grad_()
    out = module(image, *args, **kwargs)
    assert torch.isfinite(out).all(), f"non-finite output with {controls}"
    out.sum().backward()
    assert torch.isfinite(image.grad).all(), f"non-finite image gradient with {controls}"
    for name, value in controls.items():
        if isinstance(value, torch.Tensor) and value.grad is not None:
            assert torch.isfinite(value.grad).all(), f"non-finite gradient of {name} with {controls}"




@pytest.mark.parametrize("mode", list(TONE_MAPPERS))
def test_tonemap_ranges_are_safe(mode):
    @SETTINGS
    @given(images(), control_values(tg.ToneMap(mode).control_table(), skip=("mode",)))
    def check(image, controls):
        assert_finite(build(tg.ToneMap, mode, **controls), image, controls)

    check()


@pytest.mark.parametrize("aces", [False, True])
def test_color_grade_ranges_are_safe(aces):
    # log_space picks ACEScc or ACEScct for the ACES grade only; without aces it must stay at its default.
    @SETTINGS
    @given(images(), control_values(tg.ColorGrade.controls, skip=("aces",) if aces else ("aces", "log_space")))
    def check(image, controls):
        assert_finite(build(tg.ColorGrade, aces=aces, **controls), image, controls)

    check()


@pytest.mark.parametrize("style", ["linear", "log"])
def test_primary_grade_ranges_are_safe(style):
    @SETTINGS
    @given(images(), control_values(tg.PrimaryGrade(style).control_table(), skip=("style",)))
    def check(image, controls):
        assert_finite(build(tg.PrimaryGrade, style, **controls), image, controls)

    check()


@pytest.mark.parametrize("mode", BLOOM_MODES)
def test_bloom_ranges_are_safe(mode):
    @SETTINGS
    @given(images(), control_values(tg.Bloom.controls, skip=("mode",)))
    def check(image, controls):
        assert_finite(build(tg.Bloom, mode=mode, **controls), image, controls)

    check()


def test_convolution_bloom_ranges_are_safe():
    kernel = torch.ones(1, 3, 3)

    @SETTINGS
    @given(images(), control_values(tg.ConvolutionBloom(kernel).control_table(), skip=("kernel",)))
    def check(image, controls):
        assert_finite(build(tg.ConvolutionBloom, kernel, **controls), image, controls)

    check()


def test_auto_exposure_ranges_are_safe():
    @SETTINGS
    @given(images(), images(), control_values(tg.AutoExposure.controls))
    def check(first, second, controls):
        layer = build(tg.AutoExposure, **controls)
        assert_finite(layer, first, controls, dt=None)
        assert_finite(layer, second, controls, dt=1.0 / 60.0)

    check()


def test_dither_ranges_are_safe():
    @SETTINGS
    @given(images(), control_values(tg.Dither.controls))
    def check(image, controls):
        assert_finite(build(tg.Dither, **controls), image, controls)

    check()


def test_lut3d_on_any_table_within_its_bound_is_safe():
    """Entries of the extreme pixels that lie within the bound of the table's encoding (±65504 as the entries store it,
    :func:`torchgrade.lut.layer.entry_bound`); beyond it a table is refused."""
    @SETTINGS
    @given(images(), st.lists(st.sampled_from(PIXELS), min_size=81, max_size=81), control_values(tg.LUT3D.controls, skip=("compile",)),
           st.sampled_from(("trilinear", "tetrahedral")))
    def check(image, entries, controls, interpolation):
        if tg.lut.SHAPERS[controls["shaper"]].takes_curve:
            reject()  # curve shapers take their 1D tables as an argument, drawn by the cube tests
        bound = entry_bound(controls["output_encoding"])
        table = torch.tensor(entries).reshape(3, 3, 3, 3).clamp(-bound, bound).requires_grad_()
        assert_finite(tg.LUT3D(table, **controls), image, {"table": table, **controls}, interpolation=interpolation)

    check()


# ----------------------------------------------------------------------- outside the ranges


def _modules():
    return [tg.ToneMap("reinhard_extended"), tg.ColorGrade(), tg.PrimaryGrade("log"), tg.Bloom(),
            tg.ConvolutionBloom(torch.ones(1, 3, 3)), tg.AutoExposure(), tg.Dither()]


def _number_controls(module):
    return [(name, control) for name, control in module.control_table().items() if control.kind == "number"]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "above", "below"])
def test_out_of_range_raises_at_construction_and_assignment(bad):
    for module in _modules():
        for name, control in _number_controls(module):
            low, high = control.range
            assert math.isfinite(low) and math.isfinite(high), f"{type(module).__name__}.{name} has an infinite bound"
            value = {"above": high + 1.0 + abs(high), "below": low - 1.0 - abs(low)}.get(bad, bad)
            shaped = torch.full(_shape(control.default), float(value))
            with pytest.raises(ValueError, match=name):
                setattr(module, name, shaped)
            if isinstance(module, (tg.ToneMap, tg.PrimaryGrade)):
                continue  # their first argument is the mode or style, which the keyword below does not change
            with pytest.raises(ValueError, match=name):
                type(module)(**({"kernel": module.kernel} if name != "kernel" and hasattr(module, "kernel") else {}), **{name: shaped})


def test_json_infinity_is_rejected():
    config = json.loads('{"threshold": Infinity}')
    with pytest.raises(ValueError, match="threshold"):
        tg.Bloom.from_config(config)
    with pytest.raises(ValueError, match="intensity"):
        tg.ConvolutionBloom(torch.ones(1, 3, 3), intensity=1e38)


def test_a_parameter_moved_outside_its_range_raises_at_forward():
    image = torch.rand(1, 3, 4, 4)
    for module in _modules():
        for name, control in _number_controls(module):
            if getattr(module, name) is None:
                continue
            parameter = nn.Parameter(torch.as_tensor(getattr(module, name), dtype=torch.float32).clone())
            setattr(module, name, parameter)
            for bad in (math.nan, control.range[1] + 1.0 + abs(control.range[1])):
                with torch.no_grad():
                    parameter.fill_(bad)
                with pytest.raises(ValueError, match=name):
                    module(image)
            setattr(module, name, control.default)


def test_a_learnable_lut_table_that_became_nan_raises_at_forward():
    lut = tg.LUT3D(identity_table(3), learnable=True)
    with torch.no_grad():
        lut.table[0, 0, 0, 0] = math.nan
    with pytest.raises(ValueError, match="finite"):
        lut(torch.rand(1, 3, 2, 2))
    with pytest.raises(ValueError, match="finite"):
        tg.LUT3D(lut.table.detach())


@pytest.mark.parametrize("make", [lambda: tg.ColorGrade(contrast=nn.Parameter(torch.tensor(20.0))),
                                  lambda: tg.LUT3D(identity_table(3), learnable=True),
                                  lambda: tg.ConvolutionBloom(nn.Parameter(torch.ones(1, 3, 3) / 9))], ids=["grade", "lut", "convolution bloom"])
def test_a_learnable_stage_compiles_in_one_graph_before_any_eager_call(make):
    """A recorded graph carries no checks (``runtime.checks``): torch.compile with ``fullgraph=True`` of a stage that
    has never run eagerly (so holds no check's state yet) traces through its checks without a graph break."""
    stage, image = make(), torch.rand(1, 3, 4, 4)
    compiled = torch.compile(stage, backend="eager", fullgraph=True)
    with torch.no_grad():
        torch.testing.assert_close(compiled(image), stage(image))


def test_pivot_black_must_be_below_pivot_white():
    with pytest.raises(ValueError, match="pivot_black"):
        tg.PrimaryGrade("log", gamma=(2.0, 2.0, 2.0), pivot_black=0.5, pivot_white=0.5)
    grade = tg.PrimaryGrade("log", gamma=(2.0, 2.0, 2.0))
    with pytest.raises(ValueError, match="pivot_black"):
        grade.pivot_white = -1.0


def _shaped_controls():
    """Every number control whose default is a colour, trackball or matrix, by stage class."""
    from torchgrade.look.slots import STAGES

    for cls in STAGES.values():
        for name, control in cls.controls.items():
            if control.kind == "number" and isinstance(control.default, tuple):
                yield pytest.param(cls, name, control, id=f"{cls.__name__}.{name}")


@pytest.mark.parametrize("cls, name, control", list(_shaped_controls()))
def test_a_control_of_the_wrong_shape_is_refused_at_construction(cls, name, control):
    """A lift of three numbers or a 2x2 mixer was taken, and refused only at the first frame."""
    default = torch.as_tensor(control.default, dtype=torch.float64)
    short = default.flatten()[:-1].tolist() if default.dim() == 1 else default[:-1, :-1].tolist()
    from torchgrade.grading.primary import STYLE_CONTROLS

    style = {"style": next(s for s, names in STYLE_CONTROLS.items() if name in names)} if cls is tg.PrimaryGrade else {}
    with pytest.raises(ValueError, match=rf"{name} must be of shape"):
        cls(**style, **{name: short})


def test_the_log_gamma_span_is_at_least_a_thousandth_and_its_gradients_stay_finite_there():
    """Drawn with denormal pixels: pivots 6.7e-22 apart gave the pivots infinite gradients (the gamma divides by the span)."""
    with pytest.raises(ValueError, match="pivot_black must be below pivot_white by at least 0.001"):
        tg.PrimaryGrade("log", pivot_black=-6.6987e-22, pivot_white=0.0)
    pixels = torch.tensor(PIXELS)
    image = pixels[torch.randint(0, len(pixels), (1, 3, 8, 8), generator=torch.Generator().manual_seed(0))]
    controls = {"pivot_black": torch.tensor(0.5, requires_grad=True), "pivot_white": torch.tensor(0.50101, requires_grad=True),
                "gamma": torch.full((3,), 0.01, requires_grad=True), "brightness": torch.full((3,), -1023.0, requires_grad=True)}
    assert_finite(tg.PrimaryGrade("log", **controls), image, controls)


@pytest.mark.parametrize("make, name", [
    (lambda value: tg.Bloom(tint=value), "tint"),
    (lambda value: tg.ColorGrade(color_filter=value), "color_filter"),
    (lambda value: tg.ColorGrade(shadows=value, highlights=1.1), "shadows"),
    (lambda value: tg.ColorGrade(midtones=value), "midtones"),
    (lambda value: tg.PrimaryGrade(exposure=value), "exposure"),
], ids=["bloom-tint", "color-filter", "shadows", "midtones", "primary-exposure"])
def test_a_plain_number_for_a_colour_is_that_grey(make, name):
    image = torch.rand(2, 3, 16, 16) * 4
    stage, grey = make(0.8), make((0.8, 0.8, 0.8))
    assert getattr(stage, name) == (0.8, 0.8, 0.8)
    torch.testing.assert_close(stage(image), grey(image), rtol=0, atol=0)


def test_the_functional_forms_take_a_plain_number_for_a_colour_as_that_grey():
    image = torch.rand(2, 3, 16, 16) * 4
    torch.testing.assert_close(tg.functional.bloom(image, tint=0.5), tg.functional.bloom(image, tint=(0.5, 0.5, 0.5)), rtol=0, atol=0)
    torch.testing.assert_close(tg.functional.color_grade(image, color_filter=0.5),
                               tg.functional.color_grade(image, color_filter=(0.5, 0.5, 0.5)), rtol=0, atol=0)
