"""``torch.compile(..., fullgraph=True)`` of whole looks on fixed-size frames: one graph (no breaks), the same
pixels as eager. Identity shortcuts that read a control's value are decided in Python while compiling."""

import json
from pathlib import Path

import torch

import torchgrade as tg

from reference.onnx import TOLERANCE, hdr

CINEMATIC = json.loads((Path(__file__).resolve().parents[1] / "export" / "looks" / "cinematic.json").read_text())


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
