"""Per-pixel stages run in strips of rows on the CPU (``torchgrade.runtime.in_strips``): the whole frame's values to
float32 rounding, and the whole frame whenever autograd records the call or the device is not the CPU."""

import pytest
import torch

import torchgrade as tg
from torchgrade import runtime
from torchgrade.runtime import policy

HDR = "../shared/data/exr/Desk.exr"

STAGES = {
    "grade": lambda: tg.ColorGrade(aces=True, post_exposure=0.3, temperature=8, contrast=15, saturation=10,
                                   split_shadows=(0.45, 0.5, 0.56), split_highlights=(0.56, 0.5, 0.45)),
    "grade_linear": lambda: tg.ColorGrade(temperature=-30, tint=12, contrast=25, color_filter=(1.0, 0.9, 0.8)),
    "primary": lambda: tg.PrimaryGrade(saturation=1.2),
    "tonemap": lambda: tg.ToneMap("aces"),
}


@pytest.fixture(scope="module")
def desk():
    return tg.io.read_exr(HDR)[:3].unsqueeze(0)


@pytest.mark.parametrize("name", STAGES)
def test_strips_give_the_whole_frames_values(name, desk, monkeypatch):
    layer = STAGES[name]()
    with torch.no_grad():
        whole = layer(desk)
        monkeypatch.setattr(policy, "STRIP_PIXELS_PER_THREAD", 997 // torch.get_num_threads())  # strips of a few rows, the last one shorter
        strips = layer(desk)
    torch.testing.assert_close(strips, whole, rtol=1e-5, atol=1e-6)  # a matrix product may block a strip differently


def test_strips_are_skipped_when_autograd_records(desk, monkeypatch):
    monkeypatch.setattr(policy, "STRIP_PIXELS_PER_THREAD", 997 // torch.get_num_threads())
    calls = []
    image = desk[..., :64, :64].clone().requires_grad_()
    out = runtime.in_strips(lambda x: calls.append(x.shape) or x * 2.0, image)
    assert calls == [image.shape] and out.requires_grad
    learnable = torch.nn.Parameter(torch.tensor(2.0))
    runtime.in_strips(lambda x: calls.append(x.shape) or x * learnable, desk[..., :64, :64], (learnable,))
    assert calls[-1] == image.shape
    with torch.no_grad():
        runtime.in_strips(lambda x: calls.append(x.shape) or x, desk[..., :64, :64], (learnable,))
    assert len(calls) > 3
