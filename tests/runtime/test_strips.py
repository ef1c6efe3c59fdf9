"""Per-pixel stages run in strips of rows on the CPU (``torchgrade.runtime.in_strips``): the whole frame's values to
float32 rounding, with or without autograd (the same code records gradients), and the whole frame where the device is
not the CPU; a LUT's pixel runs on worker threads give the serial runs' values."""

import multiprocessing
import os
import threading

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


def test_lut_runs_on_worker_threads_give_the_serial_runs_values_and_leave_the_callers_threads_alone(desk, monkeypatch):
    lut = tg.bake_lut(tg.PostFX(grade={"contrast": 20}, tonemap="aces"), size=17, report_tolerance=float("inf"))
    image = desk[..., :200, :300]
    with torch.no_grad():
        serial = lut(image)
    monkeypatch.setattr(policy, "PARALLEL_FROM", 1)  # workers from one thread up
    threads = torch.get_num_threads()
    try:
        for count in (threads + 1, threads + 2):  # a new pool for each count: its workers set one thread each
            torch.set_num_threads(count)
            with torch.inference_mode():
                threaded = lut(image)
            assert threaded.is_inference() and torch.get_num_threads() == count
            assert torch.equal(threaded, serial)
            seen = []
            thread = threading.Thread(target=lambda: seen.append(torch.get_num_threads()))
            thread.start()
            thread.join()
            assert seen == [count]  # a thread started later begins with the caller's count, not the workers' one
    finally:
        torch.set_num_threads(threads)


def test_each_worker_computes_on_one_thread_whatever_the_callers_count():
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(threads + 3)  # a count no other test gives a pool: a new pool starts here
        seen = []
        runtime.run_pieces(lambda piece: seen.append(torch.get_num_threads()), range(8), workers=threads + 3)
        assert seen == [1] * 8 and torch.get_num_threads() == threads + 3
    finally:
        torch.set_num_threads(threads)


def _squares_on_workers(queue=None):
    out = torch.zeros(4)
    runtime.run_pieces(lambda i: out.__setitem__(i, i * i), range(4), workers=2)
    if queue is None:
        return out.tolist()
    queue.put(out.tolist())


@pytest.mark.skipif(not hasattr(os, "fork"), reason="platform-conditional: needs fork")
def test_a_forked_child_runs_pieces_on_its_own_workers():
    """A pool made before a fork holds threads that the child does not have: the child must start its own."""
    assert _squares_on_workers() == [0.0, 1.0, 4.0, 9.0]  # the parent's pool of 2 exists now
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_squares_on_workers, args=(queue,))
    child.start()
    child.join(60)
    if child.is_alive():
        child.kill()
        child.join()
    assert child.exitcode == 0, "the forked child never finished its pieces"
    assert queue.get(timeout=5) == [0.0, 1.0, 4.0, 9.0]


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
        def graded(x, *values):
            return tg.functional.color_grade(x, aces=aces, color_filter=values[-1], **dict(zip(params, values[:-1])))
        assert torch.autograd.gradcheck(graded, (image, *params.values(), color))
