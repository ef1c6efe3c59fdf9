"""``torch.compile(..., fullgraph=True)`` of whole looks on fixed-size frames: one graph (no breaks), the same
pixels as eager. Identity shortcuts that read a control's value are decided in Python while compiling."""

import json
from pathlib import Path

import pytest
import torch

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


def _captured_only(monkeypatch):
    """``tg.compile`` through Dynamo alone (backend "eager"): what these tests check is the capture, not Inductor."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda *args, **kwargs: real(*args, **{**kwargs, "backend": "eager"}))
    torch._dynamo.reset()


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
