"""What a bloom writes at the frame's size, counted on the ``meta`` device (shapes, nothing computed): each frame-sized
result is a pass over memory that no later step of the eager form can avoid reading back. The maths needs four: the
sanitized frame (NaN to 0, then the ±65504 bound), the glow upsampled to the frame, and the output; a look's bloom,
whose frame the exposure stage has already made NaN-free, three. On frames whose sides halve exactly twice (the
glow's upsampling to the frame is then bilinear's; other sides take the general expansion and smoothing a side at a
time, which write the frame a few times more)."""

import json
from pathlib import Path

import pytest
import torch

import torchgrade as tg
from torchgrade.bloom.pyramid import expand, over_blocks
from torchgrade.testing.dispatch import DispatchCount

LOOK = json.loads((Path(__file__).resolve().parents[2] / "export" / "looks" / "cinematic.json").read_text())


def frames_written(module, shape, **kwargs) -> float:
    """The frame-sized results of a second call of ``module`` on the ``meta`` device, in frames."""
    module = module.to("meta")
    frame = torch.empty(shape, device="meta")
    for _ in range(2):  # the first call makes the constants the second reuses
        with torch.no_grad(), DispatchCount(frame=frame) as counted:
            module(frame, **kwargs)
    return counted.frames_written


@pytest.mark.parametrize("mode", ["scattering", "additive"])
@pytest.mark.parametrize("shape", [(1, 3, 1080, 1920), (2, 3, 256, 384)])
def test_a_bloom_writes_the_sanitized_frame_the_glow_and_the_output(mode, shape):
    settings = {**LOOK["bloom"], "mode": mode}
    assert frames_written(tg.Bloom(**settings), shape) == 4.0
    assert frames_written(tg.Bloom(**settings), shape, nan_free=True) == 3.0


def test_the_share_scattering_keeps_scales_the_frames_blocks_as_its_expansion_does():
    """At even sides the half-resolution share multiplies each 2x2 block of the frame as a view; at odd sides it is
    expanded (:func:`~torchgrade.bloom.pyramid.expand`): the same products either way."""
    generator = torch.Generator().manual_seed(0)
    for size in [(6, 8), (5, 7)]:
        frame = torch.rand(2, 3, *size, generator=generator, dtype=torch.float64)
        level = torch.rand(2, 1, (size[0] + 1) // 2, (size[1] + 1) // 2, generator=generator, dtype=torch.float64)
        blocks, share = over_blocks(level, frame)
        torch.testing.assert_close((blocks * share).reshape(frame.shape), frame * expand(level, size), rtol=0, atol=0)
