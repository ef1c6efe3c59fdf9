"""A short training loop on crops of ``WideFloatRange.exr`` (±1.7e38, most pixels below 1e-10, denormals among them):
with every tone mapper, no step sees a non-finite loss or gradient, of the input or of any learnable control."""

from __future__ import annotations

import pytest
import torch

import torchgrade as tg
from torchgrade.testing.catalog import learnable
from torchgrade.tonemap import TONEMAP_MODES

CROP = 50
"""The side of a crop: the 500×500 frame is 100 crops; its seventh row of crops (60 to 69) holds the tiny pixels that
gave ``ToneMap("aces")``, ``"unreal_filmic"`` and ``"aces_reference"`` NaN gradients."""

GAIN_RANGE = (1e-3, 1e3)
"""Where a step keeps the gain per channel before the tone mapper."""


@pytest.fixture(scope="module")
def crops(exr_dir) -> torch.Tensor:
    """The frame cut into ``CROP``² crops, ``(100, 3, CROP, CROP)``, row by row."""
    frame = tg.io.read_exr(exr_dir / "WideFloatRange.exr")[:3]
    tiles = frame.unfold(1, CROP, CROP).unfold(2, CROP, CROP)  # (3, rows, columns, CROP, CROP)
    return tiles.permute(1, 2, 0, 3, 4).reshape(-1, 3, CROP, CROP).contiguous()


def _learnable(*stages) -> dict:
    """A gain per channel (the last layer of a network that makes the frames), at 1, and every continuous control of
    ``stages`` as parameters (:func:`~torchgrade.testing.catalog.learnable`), each with its range:
    ``{parameter: (low, high)}``, the gain first."""
    ranges = {torch.nn.Parameter(torch.ones(3, 1, 1)): GAIN_RANGE}
    for stage in stages:
        for name, parameter in learnable(stage).items():
            ranges[parameter] = stage.control_table()[name.split(".")[1]].range
    return ranges


def _train(forward, ranges: dict, crops: torch.Tensor, batch: int = 4) -> None:
    """Adam's steps towards a grey picture over ``crops``, ``batch`` at a time (the last, smaller batch too), each
    control kept inside its range after a step (as a user keeps a control that starts at a range's edge), asserting at
    each step that the loss and every gradient, the input's and each control's, are finite."""
    optimiser = torch.optim.Adam(list(ranges), lr=1e-2)
    for step, start in enumerate(range(0, len(crops), batch)):
        images = crops[start:start + batch].clone().requires_grad_()
        optimiser.zero_grad()
        loss = (forward(images, step) - 0.5).square().mean()
        loss.backward()
        assert torch.isfinite(loss), f"step {step}: loss {loss.item()}"
        assert torch.isfinite(images.grad).all(), f"step {step}: {(~torch.isfinite(images.grad)).sum().item()} non-finite input gradients"
        for parameter in ranges:
            assert torch.isfinite(parameter.grad).all(), f"step {step}: a non-finite gradient of a control"
        optimiser.step()
        with torch.no_grad():
            for parameter, (low, high) in ranges.items():
                parameter.clamp_(low, high)


@pytest.mark.parametrize("mode", TONEMAP_MODES)
def test_a_tone_mapper_trains_on_wide_float_range_crops_with_finite_gradients(crops, mode):
    tonemap = tg.ToneMap(mode)
    ranges = _learnable(tonemap)
    gain = next(iter(ranges))
    _train(lambda images, step: tonemap(images * gain), ranges, crops[::7])  # 15 crops, 63 among them


def test_random_postfx_with_every_tone_mapper_trains_on_wide_float_range_crops_with_finite_gradients(crops):
    """The augmentation as a training pipeline takes it: bloom, a grade and a tone mapper drawn per crop (the draws
    replayed with the tone mappers in turn, so that every one meets a crop)."""
    augmentation = tg.RandomPostFX(post_exposure=(-1.0, 1.0), contrast=(-30, 30), saturation=(-30, 30), hue_shift=(-90, 90),
                                   bloom_intensity=(0.0, 1.0), tonemap=list(TONEMAP_MODES), p=0.8)
    ranges = _learnable()
    gain = next(iter(ranges))
    generator = torch.Generator().manual_seed(0)
    batch = 5

    def forward(images, step):
        params = augmentation.sample_params(len(images), generator=generator)
        params["tonemap"] = (torch.arange(len(images)) + step * batch) % len(TONEMAP_MODES)
        return augmentation(images * gain, params=params)

    _train(forward, ranges, crops[::5], batch=batch)  # 20 crops: every tone mapper meets one, 60 and 65 among them
