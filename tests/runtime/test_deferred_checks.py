"""Deferred range checks (:class:`torchgrade.runtime.DeferredCheck`), their CUDA path run on the CPU.

On CUDA a value's copy to the host lands some forwards after it was made. Here a fake device stands for it: its
copies are snapshots of the value when the copy was queued (a copy runs in stream order, after the kernels
queued before it and before those queued after), and each lands ``lag`` forwards later (``lag`` = how far the
host runs ahead of the device).
"""

from __future__ import annotations

import pytest
import torch
from torch import nn

import torchgrade as tg
from torchgrade.runtime import checks


class FakeDevice:
    """Copies that land ``lag`` forwards after they were queued; :meth:`forward` advances the clock."""

    def __init__(self, lag: int):
        self.lag = lag
        self.forwards = 0
        self.copies = 0

    def forward(self) -> None:
        self.forwards += 1

    def copy_to_host(self, value: torch.Tensor):
        self.copies += 1
        return value.clone(), Landing(self, self.forwards + self.lag)


class Landing:
    def __init__(self, device: FakeDevice, due: int):
        self.device, self.due = device, due

    def query(self) -> bool:
        return self.device.forwards >= self.due


@pytest.fixture
def fake_cuda(monkeypatch):
    """Every value takes the deferred (CUDA) path, copied by a :class:`FakeDevice` (``lag`` set by the test)."""
    device = FakeDevice(lag=1)
    monkeypatch.setattr(checks, "_deferred", lambda where: True)
    monkeypatch.setattr(checks, "_copy_to_host", device.copy_to_host)
    return device


def in_range(name: str, value: torch.Tensor) -> None:
    if not 0.0 <= float(value) <= 10.0:
        raise ValueError(f"{name} must lie in [0, 10], got {float(value)}")


def raised_at(device: FakeDevice, steps, value: torch.Tensor, check=None) -> list:
    """The forwards (0-based) whose check raised, ``steps[i](value)`` run before forward ``i`` (an optimiser step)."""
    check = check or checks.DeferredCheck()
    raised = []
    for index, step in enumerate(steps):
        device.forward()
        with torch.no_grad():
            step(value)
        try:
            check({"gain": value}, in_range)
        except ValueError:
            raised.append(index)
    return raised


def keep(value):
    pass


def out_of_range(value):
    value.fill_(50.0)


def back_in_range(value):
    value.fill_(2.0)


def further_out(value):
    value.add_(1.0)  # still out of range


def test_a_host_running_two_forwards_ahead_still_reports_a_value_moved_out_of_range(fake_cuda):
    fake_cuda.lag = 2  # every forward's copy lands after the next forward has queued its own
    raised = raised_at(fake_cuda, [keep, out_of_range] + [further_out] * 6, nn.Parameter(torch.tensor(1.0)))
    assert raised == [3, 4, 5, 6, 7]  # out from forward 1 on: each forward's copy raises as it lands, two forwards on


def test_a_value_left_out_of_range_raises_at_every_forward_after_the_first_report(fake_cuda):
    raised = raised_at(fake_cuda, [keep, out_of_range] + [keep] * 6, nn.Parameter(torch.tensor(1.0)))
    assert raised == [2, 3, 4, 5, 6, 7]  # out at forward 1, its copy landed at 2; then as the CPU raises


def test_a_forward_that_ran_out_of_range_is_reported_though_the_value_came_back_before_its_copy_landed(fake_cuda):
    raised = raised_at(fake_cuda, [keep, out_of_range, back_in_range] + [keep] * 4, nn.Parameter(torch.tensor(1.0)))
    assert raised == [2]  # forward 1 computed with 50: its copy lands at forward 2


def test_a_value_restored_raises_no_more_once_the_copies_made_out_of_range_have_landed(fake_cuda):
    raised = raised_at(fake_cuda, [keep, out_of_range, keep, back_in_range] + [keep] * 4, nn.Parameter(torch.tensor(1.0)))
    assert raised == [2, 3]


def test_each_copy_is_checked_by_the_check_its_caller_gave(fake_cuda):
    shared = checks.DeferredCheck()
    seen = []
    gain, kernel = nn.Parameter(torch.tensor(1.0)), nn.Parameter(torch.ones(1, 3, 3))
    for _ in range(3):
        fake_cuda.forward()
        shared({"gain": gain}, lambda name, value: seen.append(("number check", name)))
        shared({"kernel": kernel}, lambda name, value: seen.append(("kernel check", name)))
    assert sorted(set(seen)) == [("kernel check", "kernel"), ("number check", "gain")]


def test_a_nan_kernel_is_reported_when_a_number_control_is_learnable_too(fake_cuda):
    stage = tg.ConvolutionBloom(nn.Parameter(torch.ones(1, 3, 3)), intensity=nn.Parameter(torch.tensor(0.5)))
    image = torch.rand(1, 3, 8, 8)
    fake_cuda.forward()
    stage(image)
    with torch.no_grad():
        stage.kernel.fill_(float("nan"))
    with pytest.raises(ValueError, match="kernel"):
        for _ in range(fake_cuda.lag + 2):
            fake_cuda.forward()
            stage(image)


def test_a_stage_out_of_range_on_the_device_raises_its_own_message(fake_cuda):
    grade = tg.ColorGrade(contrast=nn.Parameter(torch.tensor(20.0)))
    image = torch.rand(1, 3, 4, 4)
    fake_cuda.forward()
    grade(image)
    with torch.no_grad():
        grade.contrast.fill_(500.0)
    fake_cuda.forward()
    grade(image)  # the copy of 500 is on its way
    fake_cuda.forward()
    with pytest.raises(ValueError, match=r"contrast must lie in \[-100.0, 100.0\], got 500.0"):
        grade(image)


def test_on_the_cpu_every_forward_checks_at_once():
    check = checks.DeferredCheck()
    gain = nn.Parameter(torch.tensor(50.0))
    for _ in range(3):
        with pytest.raises(ValueError, match="gain must lie"):
            check({"gain": gain}, in_range)
