"""``tg.compile`` in a training epoch: one graph for every batch size, and a compile that says so.

The compiles are counted by the wrapper's own announcements (the ``torchgrade.compile`` logger), and at inference by
Dynamo's counter of the frames it compiles too; through Dynamo and AOTAutograd (``CompileCounterWithBackend``), without
Inductor's code generation, which takes minutes on a 2-core machine.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from torch._dynamo.testing import CompileCounterWithBackend

import torchgrade as tg
from torchgrade.runtime.compile import COMPILE_SECONDS

ROOT = Path(__file__).resolve().parents[2]
BATCHES = (16, 15, 8)
"""An epoch's batches: the first, its last (smaller) one, and a validation batch."""
LOOK = {"exposure": {"metering": "log"}, "bloom": {"intensity": 0.5}, "grade": {"contrast": 15, "hue_shift": 10}, "tonemap": "aces"}
"""A look with the stages whose compiled forms tied a graph to its batch (exposure, bloom)."""


def _counted(monkeypatch, backend: str) -> CompileCounterWithBackend:
    """``torch.compile`` through Dynamo's counter of compiled frames, on ``backend`` (Inductor's options left out)."""
    counter = CompileCounterWithBackend(backend)
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda *args, options=None, **kwargs: real(*args, **{**kwargs, "backend": counter}))
    torch._dynamo.reset()
    return counter


def _augmentation() -> tg.RandomPostFX:
    return tg.RandomPostFX(post_exposure=(-1.0, 1.0), contrast=(-20, 20), saturation=(-20, 20), hue_shift=(-30, 30),
                           bloom_intensity=(0.0, 1.0), tonemap=["aces", "neutral"], p=0.8)


def _started(caplog) -> list:
    return [record.getMessage() for record in caplog.records if record.getMessage().startswith("compiling")]


@pytest.mark.parametrize("case", ["augmentation", "look training step"])
def test_an_epochs_batches_of_16_15_and_8_run_one_graph(case, monkeypatch, caplog):
    """The augmentation with bloom, hue and two tone mappers (inference), and a look's training step (forward and
    backward; exposure metering each batch afresh, bloom, a grade with hue, ACES): one compile for every batch, of the
    forward and of the backward. They compiled again for the batch of 15 before: the bloom pyramid's blur, a
    convolution while compiling, had its backend chosen by the batch (oneDNN from 16 frames), and the exposure stage's
    state, the last batch's shape, was tied to the batch's."""
    training = case == "look training step"
    counter = _counted(monkeypatch, "aot_eager" if training else "eager")
    compiled = tg.compile(tg.PostFX(**LOOK) if training else _augmentation())
    with caplog.at_level("INFO", logger="torchgrade.compile"):
        for batch in BATCHES:
            image = (torch.rand(batch, 3, 32, 32, generator=torch.Generator().manual_seed(batch)) * 4).requires_grad_(training)
            with torch.set_grad_enabled(training):
                out = compiled(image)
            if training:
                out.mean().backward()
                assert image.grad.isfinite().all()
    assert [message.split(" for ")[0] for message in _started(caplog)] == (
        ["compiling the forward of PostFX", "compiling the backward of PostFX"] if training else ["compiling the forward of RandomPostFX"])
    if not training:  # Dynamo's own count (in training, AOTAutograd's first pass over the graph restarts it once)
        assert counter.frame_count == 1


def test_a_recompile_names_the_guard_that_failed_and_each_compile_its_time_and_cost(monkeypatch, caplog):
    """With sizes fixed (``dynamic=False``) a second batch compiles again; it says which guard failed. A training call's
    backward says when it compiles, at its first ``backward()``."""
    _counted(monkeypatch, "aot_eager")
    compiled = tg.compile(tg.ToneMap("reinhard"), dynamic=False)
    with caplog.at_level("INFO", logger="torchgrade.compile"):
        for batch in (4, 3, 3):
            compiled(torch.rand(batch, 3, 4, 4, requires_grad=True)).sum().backward()
    first, first_end, backward, backward_end, second, second_end, *rest = (record.getMessage() for record in caplog.records)
    cost = ("a compile of a whole look in training took 93.4 s cold, 8.6 s from Inductor's cache, on 2 CPU threads "
            "(benchmarks/results/compile.md)")
    assert first == f"compiling the forward of ToneMap for a (4, 3, 4, 4) float32 frame on cpu, gradients on (its first frame); {cost}"
    assert re.fullmatch(r"compiled the forward of ToneMap for a \(4, 3, 4, 4\) .* in \d+\.\d s", first_end)
    assert backward.startswith("compiling the backward of ToneMap for a (4, 3, 4, 4)")
    assert re.fullmatch(r"compiled the backward of .* in \d+\.\d s", backward_end)
    assert re.match(r"compiling the forward of ToneMap for a \(3, 3, 4, 4\) .*\(a guard of its last graph failed: "
                    r".*size mismatch at index 0\. expected 4, actual 3", second), second
    assert second_end.startswith("compiled the forward of ToneMap for a (3, 3, 4, 4)")
    assert [message for message in rest if "forward" in message] == []  # the third call ran the second graph


def test_a_compile_is_quiet_with_verbose_false_or_the_loggers_level(monkeypatch, caplog):
    _counted(monkeypatch, "eager")
    with caplog.at_level("INFO", logger="torchgrade.compile"):
        tg.compile(tg.ToneMap("reinhard"), verbose=False)(torch.rand(2, 3, 4, 4))
    with caplog.at_level("WARNING", logger="torchgrade.compile"):
        tg.compile(tg.ToneMap("hable"))(torch.rand(2, 3, 4, 4))
    assert caplog.records == []


@pytest.mark.parametrize("quiet", [False, True], ids=["default", "logger at WARNING"])
def test_a_compile_is_told_on_stderr_by_default(quiet):
    """In a program that has not configured logging: a line on stderr when the compile starts and one when it ends,
    none with the library's logger at WARNING (Dynamo alone, through PyTorch's public stance, to keep it short)."""
    script = f"""
import logging, torch, torchgrade as tg
if {quiet}:
    logging.getLogger("torchgrade.compile").setLevel(logging.WARNING)
torch.compiler.set_stance("default", force_backend="eager")
tg.compile(tg.ToneMap("reinhard"))(torch.rand(2, 3, 4, 4))
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert run.returncode == 0, run.stderr[-2000:]
    lines = [line for line in run.stderr.splitlines() if line.startswith("torchgrade: ")]
    if quiet:
        assert lines == []
    else:
        assert len(lines) == 2 and lines[0].startswith("torchgrade: compiling the forward of ToneMap for a (2, 3, 4, 4)")
        assert re.fullmatch(r"torchgrade: compiled the forward of ToneMap .* in \d+\.\d s", lines[1])


def test_the_announced_costs_are_the_committed_measurements():
    results = json.loads((ROOT / "benchmarks" / "results" / "compile.json").read_text())
    cases = {("PostFX", False): "look 1x3x1080x1920", ("PostFX", True): "look training 16x3x128x128",
             ("RandomPostFX", False): "RandomPostFX 64x3x224x224", ("RandomPostFX", True): "RandomPostFX training 16x3x128x128"}
    assert COMPILE_SECONDS.keys() == cases.keys()
    for key, case in cases.items():
        assert COMPILE_SECONDS[key] == tuple(round(results[case][cache]["first_call_s"], 1) for cache in ("cold", "warm"))


@pytest.mark.parametrize("side, compiles", [(24, 1), (16, 2)])
def test_a_batch_equal_to_a_side_of_the_first_frame_is_tied_to_it(side, compiles, monkeypatch, caplog):
    """The cost of ``dynamic=True`` that ``docs/gpu.md`` states: PyTorch ties sizes equal at the first frame (duck
    sizing), so a batch of 16 on 16x16 frames compiles again for a batch of 15; on 24x24 frames it does not."""
    _counted(monkeypatch, "eager")
    compiled = tg.compile(tg.ToneMap("reinhard"), dynamic=True)
    with caplog.at_level("INFO", logger="torchgrade.compile"), torch.no_grad():
        for batch in (16, 15):
            compiled(torch.rand(batch, 3, side, side))
    assert len(_started(caplog)) == compiles


@pytest.mark.parametrize("side", [16, 24])
def test_the_batch_alone_is_symbolic_by_default(side, monkeypatch, caplog):
    """By default the batch is symbolic and the sides fixed: a batch of 15 after 16 runs the first graph whatever the
    sides (no duck sizing ties them), and a frame of new sides compiles once more."""
    _counted(monkeypatch, "eager")
    compiled = tg.compile(tg.ToneMap("reinhard"))
    with caplog.at_level("INFO", logger="torchgrade.compile"), torch.no_grad():
        for batch, height in ((16, side), (15, side), (8, side), (8, side + 1)):
            compiled(torch.rand(batch, 3, height, side))
    assert [re.search(r"\((\d+), 3, (\d+), (\d+)\)", message).groups() for message in _started(caplog)] == [
        ("16", str(side), str(side)), ("8", str(side + 1), str(side))]


def test_a_stage_state_of_the_batch_shape_is_symbolic_with_the_batch(monkeypatch, caplog):
    """An exposure stage's state has the batch's shape (``batch_state``): sequences of batches 4, 3 and 2 run one
    graph, their second frames (which read the state the first wrote) included, and give what the stage gives."""
    counter = _counted(monkeypatch, "eager")
    stage, eager = tg.AutoExposure(speed=2.0), tg.AutoExposure(speed=2.0)
    compiled = tg.compile(stage)
    with caplog.at_level("INFO", logger="torchgrade.compile"), torch.no_grad():
        for batch in (4, 3, 2):
            for frame in range(2):
                image = torch.rand(batch, 3, 8, 8, generator=torch.Generator().manual_seed(batch + frame)) * 4
                torch.testing.assert_close(compiled(image, dt=1 / 24), eager(image, dt=1 / 24))
            stage.reset()
            eager.reset()
    assert len(_started(caplog)) == 1 and counter.frame_count == 1


def test_compiling_a_look_of_sequence_controls_warns_of_no_cache(recwarn):
    """A stage asks whether each control is its identity at every call, a sequence's answer cached eagerly; Dynamo
    traces the comparison itself and has no cache to warn of (it warns once a process of any it looks through)."""
    look = tg.PostFX(grade={"split_shadows": (0.2, 0.4, 0.9), "split_highlights": (1.0, 0.8, 0.6), "contrast": 10}).eval()
    image = torch.rand(1, 3, 8, 8)
    torch._dynamo.reset()
    with torch.no_grad():
        torch.testing.assert_close(torch.compile(look, backend="eager", fullgraph=True)(image), look(image))
    assert not [w for w in recwarn if "lru_cache" in str(w.message)]
