"""One ``AutoExposure`` serving several streams from several threads keeps each stream's adaptation its own."""

from __future__ import annotations

import threading

import pytest
import torch

import torchgrade as tg

FRAMES = 40
DT = 1.0 / 30.0


def _sequence(level: float, cut: int, factor: float) -> list:
    """A stream at ``level`` that cuts to ``factor`` times it at frame ``cut`` (adaptation is then under way)."""
    return [torch.full((1, 3, 4, 4), level * (1.0 if i < cut else factor)) for i in range(FRAMES)]


def _alone(frames: list) -> list:
    layer = tg.AutoExposure(metering="mean")
    return [layer(frame, dt=DT) for frame in frames]


def _served(layer, frames: list, stream, outputs: list, start: threading.Barrier) -> None:
    start.wait()
    for frame in frames:
        outputs.append(layer(frame, dt=DT, stream=stream))


def test_two_threads_on_two_streams_adapt_as_if_alone():
    sequences = {"dark": _sequence(0.05, 5, 16.0), "bright": _sequence(4.0, 12, 1.0 / 16.0)}
    layer = tg.AutoExposure(metering="mean")
    outputs = {key: [] for key in sequences}
    start = threading.Barrier(len(sequences))
    threads = [threading.Thread(target=_served, args=(layer, frames, key, outputs[key], start)) for key, frames in sequences.items()]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for key, frames in sequences.items():
        for got, expected in zip(outputs[key], _alone(frames), strict=True):
            torch.testing.assert_close(got, expected, rtol=0, atol=0)
    assert layer.adapted_luminance.numel() == 0, "streams must not touch the default sequence"


def test_streams_are_independent_of_the_default_sequence_and_reset_separately():
    layer = tg.AutoExposure(metering="mean")
    layer(torch.full((1, 3, 2, 2), 0.5))
    layer(torch.full((1, 3, 2, 2), 4.0), dt=0.1, stream="cam")
    assert layer.adapted_luminance.item() == pytest.approx(0.5)
    assert layer.streams["cam"].item() == pytest.approx(4.0)
    layer.reset("cam")
    assert "cam" not in layer.streams and layer.adapted_luminance.numel() == 1
    layer(torch.full((1, 3, 2, 2), 4.0), dt=0.1, stream="cam")
    layer.reset()
    assert layer.adapted_luminance.numel() == 0 and not layer.streams


def test_a_stream_keeps_the_batch_rule():
    layer = tg.AutoExposure()
    layer(torch.rand(2, 3, 4, 4), dt=0.1, stream=7)
    with pytest.raises(ValueError, match="batch changed"):
        layer(torch.rand(3, 3, 4, 4), dt=0.1, stream=7)
