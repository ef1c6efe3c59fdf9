"""``torch.compile(..., fullgraph=True)`` of whole looks on fixed-size frames: one graph (no breaks), the same
pixels as eager. Identity shortcuts that read a control's value are decided in Python while compiling."""

import itertools
import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch
import torch._dynamo.testing

import torchgrade as tg

from reference.onnx import TOLERANCE, hdr

CINEMATIC = json.loads((Path(__file__).resolve().parents[2] / "export" / "looks" / "cinematic.json").read_text())


def test_the_cinematic_frame_compiles_as_one_graph():
    look = tg.PostFX.from_config(CINEMATIC).eval()
    inputs = (hdr((1, 3, 40, 56)), torch.zeros(1), torch.tensor(0.2))
    with torch.no_grad():  # fullgraph=True raises at the first graph break
        compiled = torch.compile(look.frame, fullgraph=True)(*inputs)
        expected = look.frame(*inputs)
    for got, want in zip(compiled, expected):
        torch.testing.assert_close(got, want, atol=TOLERANCE, rtol=TOLERANCE)


def test_a_look_module_is_captured_as_one_graph():
    """The module form, captured by Dynamo alone (backend "eager": the capture is what can break)."""
    look = tg.PostFX(bloom={"intensity": 0.5, "tint": (1.0, 0.9, 0.8)}, grade={"contrast": 20, "aces": True},
                     tonemap="aces").eval()
    image = hdr((2, 3, 24, 32))
    with torch.no_grad():
        torch.testing.assert_close(torch.compile(look, fullgraph=True, backend="eager")(image), look(image), atol=TOLERANCE, rtol=TOLERANCE)


def _captured_only(monkeypatch, backend="eager"):
    """``tg.compile`` through ``backend`` (Dynamo alone by default): what these tests check is the capture, not Inductor
    (whose ``options`` are left out)."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda *args, options=None, **kwargs: real(*args, **{**kwargs, "backend": backend}))
    torch.compiler.reset()


def test_tg_compile_runs_more_frame_sizes_than_dynamos_recompile_limit(monkeypatch):
    _captured_only(monkeypatch)
    stage = tg.ToneMap("reinhard")
    compiled = tg.compile(stage)
    sizes = torch._dynamo.config.recompile_limit + 2  # with one graph per size, the limit+1-th size fails
    with torch.no_grad():
        for side in range(8, 8 + sizes):
            image = hdr((1, 3, side, side + 1))
            torch.testing.assert_close(compiled(image), stage(image), atol=TOLERANCE, rtol=TOLERANCE)


def test_a_compiled_stage_checks_its_learnable_controls_at_every_call(monkeypatch):
    _captured_only(monkeypatch)
    look = tg.PostFX(grade=tg.ColorGrade(contrast=torch.nn.Parameter(torch.tensor(20.0))), tonemap="reinhard")
    compiled = tg.compile(look)
    image = hdr((1, 3, 8, 8))
    compiled(image)
    with torch.no_grad():
        look.grade.contrast.fill_(500.0)  # what an optimiser step could do
    with pytest.raises(ValueError, match=r"contrast must lie in \[-100.0, 100.0\], got 500.0"):
        compiled(image)


@pytest.mark.parametrize("dt", [None, 1 / 24])
def test_a_compiled_look_with_exposure_compiles_once_and_adapts_as_eager(monkeypatch, dt):
    """The exposure state is empty before the first frame and takes the batch's shape after it: compiled, the second
    frame must run the first frame's graph (Dynamo guards the state's shape), with eager's values and state."""
    from torch._dynamo.testing import CompileCounter

    counter = CompileCounter()
    _captured_only(monkeypatch, counter)
    config = {"exposure": CINEMATIC["exposure"], "tonemap": {"mode": "reinhard"}}
    eager, compiled_look = tg.PostFX.from_config(config).eval(), tg.PostFX.from_config(config).eval()
    compiled = tg.compile(compiled_look)
    frames = [hdr((2, 3, 16, 24)) * scale for scale in (1.0, 4.0, 0.25)]
    for frame in frames:
        with torch.no_grad():
            torch.testing.assert_close(compiled(frame, dt), eager(frame, dt), atol=TOLERANCE, rtol=TOLERANCE)
        torch.testing.assert_close(compiled_look.exposure.adapted_luminance, eager.exposure.adapted_luminance)
    assert counter.frame_count == 1


def _as_close_to_float64_as_eager(compiled, eager, exact) -> bool:
    """Whether the compiled gradient is as close to the float64 one as float32 eager's is: within 1.5 times eager's
    largest error, or within float32's rounding as the grade amplifies it (2e-4 of the gradient's peak). Two float32
    forms of the same maths differ at a few pixels where the grade magnifies rounding: over five frames the ratio of
    their largest errors ranged 0.5-2.6 (0.5-3.5 since bloom's pyramid spans the frame), each under 6e-4 of the peak."""
    largest_error = (compiled - exact).abs().max()
    return bool(largest_error <= 1.5 * (eager - exact).abs().max() + 1e-7 or largest_error <= 2e-4 * exact.abs().max())


def test_a_compiled_look_trains_as_eager(monkeypatch):
    """Forward and backward through ``tg.compile`` (AOTAutograd's joint graph; backend "aot_eager" runs it without
    Inductor): the image's gradient is as close to a float64 eager gradient as float32 eager's is."""
    _captured_only(monkeypatch, "aot_eager")
    look = tg.PostFX.from_config(CINEMATIC).eval()
    frame = hdr((1, 3, 24, 32))

    def gradient(call, dtype=torch.float32):
        image = frame.to(dtype, copy=True).requires_grad_()
        call(image).sum().backward()
        return image.grad.double()

    compiled, eager = gradient(tg.compile(look)), gradient(look)
    exact = gradient(tg.PostFX.from_config(CINEMATIC).eval().double(), torch.float64)
    assert exact.abs().max() > 0.1  # a gradient the comparison can see
    assert _as_close_to_float64_as_eager(compiled, eager, exact)


def test_a_compiled_training_step_keeps_its_gradient_at_the_extremes(monkeypatch):
    """What the compiled backward recomputes changes no image gradient, on every combination of three extreme values
    (0, denormals, grey, 60, 65504, 1e30, 3e38) and on NaN, ±Inf and negative pixels: finite, and as close to the float64
    eager gradient as float32 eager's (AOTAutograd's partitioner, without Inductor)."""
    from torchgrade.testing.extremes import EXTREME_VALUES

    grid = torch.tensor(list(itertools.product(EXTREME_VALUES, repeat=3))).T.reshape(1, 3, 36, 48)
    grid[0, :, 0, :4] = torch.tensor([[float("nan"), float("inf"), -float("inf"), -2.0]] * 3)

    def gradient(call, dtype=torch.float32):
        image = grid.to(dtype, copy=True).requires_grad_()
        call(image).sum().backward()
        return image.grad.double()

    _captured_only(monkeypatch, "aot_eager_decomp_partition")
    compiled = gradient(tg.compile(tg.PostFX.from_config(CINEMATIC).eval()))
    eager = gradient(tg.PostFX.from_config(CINEMATIC).eval())
    exact = gradient(tg.PostFX.from_config(CINEMATIC).eval().double(), torch.float64)
    assert compiled.isfinite().all() and exact.abs().max() > 1e-3
    assert _as_close_to_float64_as_eager(compiled, eager, exact)


def test_a_compiled_frame_that_fails_leaves_the_exposure_state_empty_and_a_stream_leaves_it_alone(monkeypatch):
    _captured_only(monkeypatch)
    stage = tg.AutoExposure(speed=1.5)
    compiled = tg.compile(stage)
    with pytest.raises(ValueError, match="dt must lie"):
        compiled(hdr((2, 3, 8, 8)), -1.0)
    assert stage.adapted_luminance.numel() == 0
    compiled(hdr((4, 3, 8, 8)), 0.5, stream="cam")
    assert stage.adapted_luminance.numel() == 0 and stage.streams["cam"].shape == (4,)
    compiled(hdr((3, 3, 8, 8)), 0.5)  # a first frame of another batch: no sequence to break
    assert stage.adapted_luminance.shape == (3,)



@pytest.mark.parametrize("name", ["stage", "look", "lut", "augmentation"])
@pytest.mark.parametrize("frame, error, message", [
    (torch.rand(1, 2, 8, 8), ValueError, "3 colour channels"),
    (torch.randint(0, 255, (1, 3, 8, 8), dtype=torch.uint8), TypeError, "floating-point"),
], ids=["two-channels", "eight-bit"])
def test_a_compiled_module_refuses_a_frame_with_the_error_eager_mode_gives(monkeypatch, name, frame, error, message):
    """Dynamo reports an exception raised while tracing as its own ``Unsupported``; ``tg.compile`` raises the module's."""
    _captured_only(monkeypatch)
    module = {"stage": lambda: tg.ToneMap("aces"), "look": lambda: tg.PostFX.from_config(CINEMATIC).eval(),
              "lut": lambda: tg.LUT3D(tg.lut.identity_table(5)), "augmentation": lambda: tg.RandomPostFX(contrast=20)}[name]()
    with pytest.raises(error, match=message) as eager:
        module(frame)
    with pytest.raises(error, match=message) as compiled:
        tg.compile(module)(frame)
    assert str(compiled.value) == str(eager.value) and compiled.value.__context__ is None


def test_a_compiled_module_refuses_a_frame_that_is_not_a_tensor_as_eager_mode_does(monkeypatch):
    _captured_only(monkeypatch)
    with pytest.raises(TypeError, match="torch.Tensor") as eager:
        tg.ToneMap("aces")(np.zeros((1, 3, 4, 4), dtype=np.float32))
    with pytest.raises(TypeError, match="torch.Tensor") as compiled:
        tg.compile(tg.ToneMap("aces"))(np.zeros((1, 3, 4, 4), dtype=np.float32))
    assert str(compiled.value) == str(eager.value)


class _RefusesOnlyWhileTraced(torch.nn.Module):
    """Raises while Dynamo traces it, not eagerly: a frame the compiled graph cannot run."""

    def forward(self, image):
        if torch.compiler.is_compiling():
            raise ValueError("only while traced")
        return image * 2.0


def test_a_frame_only_the_trace_refuses_raises_the_compiles_error(monkeypatch):
    """A compile that fails on a frame the module takes eagerly is not hidden behind an eager run."""
    _captured_only(monkeypatch)
    with pytest.raises(RuntimeError, match="only while traced"):
        tg.compile(_RefusesOnlyWhileTraced())(torch.ones(1, 3, 2, 2))


def test_cpu_frames_compile_without_inductors_layout_optimisation(monkeypatch):
    settings = {}
    monkeypatch.setattr(torch, "compile", lambda module, **kwargs: settings.update(kwargs) or module)
    tg.compile(tg.ToneMap("aces"))(torch.rand(1, 3, 4, 4))
    assert settings["options"] == {"layout_optimization": False} and "mode" not in settings and settings["fullgraph"]


def test_a_last_smaller_batch_runs_the_first_graph_and_each_compile_is_logged(monkeypatch, caplog):
    """Sizes are symbolic from the first frame: batches of 4, 3 and 2 compile once (a batch of 1, which PyTorch
    specialises as it does every size 1, would compile its own graph); the compile is announced on the
    ``torchgrade.compile`` logger, naming the module, the frame, the gradients and why, and then how long it took."""
    counter = torch._dynamo.testing.CompileCounter()
    _captured_only(monkeypatch, counter)
    compiled = tg.compile(tg.PostFX(grade={"contrast": 20}, tonemap="aces"))
    with caplog.at_level("INFO", logger="torchgrade.compile"), torch.no_grad():
        for batch in (4, 3, 2, 4):
            image = hdr((batch, 3, 16, 24))
            torch.testing.assert_close(compiled(image), compiled.module(image), atol=TOLERANCE, rtol=TOLERANCE)
    assert counter.frame_count == 1
    started, ended = (record.getMessage() for record in caplog.records)
    assert started.startswith("compiling the forward of PostFX for a (4, 3, 16, 24) float32 frame on cpu, gradients off "
                              "(its first frame)")
    assert re.fullmatch(r"compiled the forward of PostFX .* in \d+\.\d s", ended)


def test_warm_up_compiles_before_the_first_frame(monkeypatch):
    counter = torch._dynamo.testing.CompileCounter()
    _captured_only(monkeypatch, counter)
    compiled = tg.compile(tg.ToneMap("aces"))
    seconds = compiled.warm_up(hdr((2, 3, 8, 8)), training=True)
    assert seconds > 0 and counter.frame_count == 1
    image = hdr((5, 3, 8, 8)).requires_grad_()
    compiled(image).sum().backward()
    assert counter.frame_count == 1 and image.grad.isfinite().all()


@pytest.mark.parametrize("gradients", [False, True])
def test_warm_up_for_inference_compiles_for_the_callers_gradient_mode(monkeypatch, gradients):
    """Dynamo guards on the gradient mode: a warm-up in another mode than the frames' would compile twice."""
    counter = torch._dynamo.testing.CompileCounter()
    _captured_only(monkeypatch, counter)
    compiled = tg.compile(tg.ToneMap("aces"))
    with torch.set_grad_enabled(gradients):
        compiled.warm_up(hdr((2, 3, 8, 8)))
        compiled(hdr((5, 3, 8, 8)))
    assert counter.frame_count == 1
