"""Per-pixel stages run in strips of rows on the CPU (``torchgrade.runtime.in_strips``): the whole frame's values to
float32 rounding, with or without autograd (the same code records gradients), and the whole frame where the device is
not the CPU."""

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


def test_strips_record_gradients_as_the_whole_frame_does(desk, monkeypatch):
    """A frame that records gradients runs on strips too (eager and autograd run the same code), joined by a
    concatenation autograd records: the whole frame's values and gradients."""
    layer, image = STAGES["grade"](), desk[..., :64, :64]

    def run():
        x = image.clone().requires_grad_()
        out = layer(x)
        out.square().sum().backward()
        return out.detach(), x.grad

    monkeypatch.setattr(policy, "STRIP_PIXELS_PER_THREAD", 1 << 20)  # one strip: the whole frame
    whole = run()
    calls = []
    monkeypatch.setattr(policy, "STRIP_PIXELS_PER_THREAD", 997 // torch.get_num_threads())
    assert runtime.in_strips(lambda x: calls.append(x.shape) or x, image.clone().requires_grad_()).requires_grad
    assert len(calls) > 3
    for stripped, expected in zip(run(), whole):
        torch.testing.assert_close(stripped, expected, rtol=1e-5, atol=1e-6)


def test_other_devices_compute_whole_frames():
    assert runtime.policy_for(torch.device("meta")).strip_pixels is None
    calls = []
    image = torch.empty(1, 3, 2000, 2000, device="meta")
    runtime.in_strips(lambda x: calls.append(x.shape) or x, image)
    assert calls == [image.shape]


def test_gradients_of_the_folded_grade_match_finite_differences():
    torch.manual_seed(0)
    image = (torch.rand(1, 3, 3, 4, dtype=torch.float64) * 2.0 + 0.05).requires_grad_()
    params = {name: torch.tensor(value, dtype=torch.float64, requires_grad=True)
              for name, value in (("post_exposure", 0.3), ("temperature", 8.0), ("tint", -5.0), ("contrast", 15.0))}
    color = torch.tensor((1.0, 0.9, 0.8), dtype=torch.float64, requires_grad=True)
    for aces in (False, True):
        def graded(x, *values, aces=aces):
            return tg.functional.color_grade(x, aces=aces, color_filter=values[-1], **dict(zip(params, values[:-1])))
        assert torch.autograd.gradcheck(graded, (image, *params.values(), color))
