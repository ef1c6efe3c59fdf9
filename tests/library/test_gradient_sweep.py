"""Finite, bounded gradients on every finite input: the dense sweep through everything the library ships.

The sweep (:func:`torchgrade.testing.extremes.sweep_frame`) is every power of ten a dtype holds, from its smallest
denormal to its largest finite value, in single channels, grey, mixed with 1.0 and 0.18, and negated: one frame per
dtype. It runs through every stage of :data:`~torchgrade.testing.catalog.STAGE_KINDS` (every tone mapper among them),
the shipped looks (``export/looks/*.json``) and ``RandomPostFX`` with every control, in float32, float16 and
bfloat16, eagerly and in the forms a compiled graph runs (``torch.compiler.is_compiling()`` answering yes: the
execution policy's planes forms), with every continuous control an ``nn.Parameter``
(:func:`~torchgrade.testing.catalog.learnable`).

Every output and every gradient (the image's and each control's) is finite, and bounded by the derivatives of the
same stage in float64 on the same pixels (its output bounded to the dtype's range, as the stage returns it): no
gradient of a stage is more than :data:`GROWTH` times the largest float64 one, where float32's, float16's or
bfloat16's rounding would otherwise show as an overflowing division or power; and no image gradient, float64's
included, passes :data:`IMAGE_BOUND`, nor near black a tone mapper's :data:`NEAR_BLACK_BOUND`.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import pytest
import torch

import torchgrade as tg
from torchgrade.base.images import HALF_MAX
from torchgrade.testing.catalog import STAGE_KINDS, learnable
from torchgrade.testing.extremes import NEAR_BLACK, sweep_frame
from torchgrade.tonemap import TONEMAP_MODES

LOOKS = sorted((Path(__file__).resolve().parents[2] / "export" / "looks").glob("*.json"))
DTYPES = (torch.float32, torch.float16, torch.bfloat16)
FORMS = ("eager", "compiled")

GROWTH = 2.0
"""How far a gradient may exceed the largest float64 gradient of the same stage on the same pixels: float32's rounding
moves the sweep's largest gradients by at most 1.3 times (a control's derivative that cancels to 0 in float64 is
float32's rounding of the sum, bounded by :data:`ROUNDING` instead)."""

ROUNDING = 1e-6
"""A gradient that float64 finds 0 is allowed this times the sum of the output's magnitudes: the rounding of a sum of
per-pixel derivatives, each at most of the output's size, in float32 (8 units of its last place)."""

IMAGE_BOUND = 2.0 * HALF_MAX
"""Every image gradient of every stage on the sweep, float64's included (the curves' own derivatives): a pixel's
channels are bounded to ±65504 before any stage, and the largest gradients are a channel of that size times a slope
of order 1 (bloom's: a pixel's -65504 times its soft-knee fraction's slope, 6.4e4). A cubic or a power whose slope
grows without bound breaks it (soft-light's cubic gave 4.8e9 at -1e4, PQ's power 8e30 at a denormal)."""

NEAR_BLACK_BOUND = 1e4
"""Every tone mapper's image gradient on pixels within :data:`~torchgrade.testing.extremes.NEAR_BLACK` of black, in
every dtype and form. The float64 derivatives of the curves themselves reach 7.9e3 there (ACES, Unity's fit: its
dim-surround step floors ``x + y + z`` and ``y`` at 1e-4 in xyY, below which its ``Z`` is ``(1 - x - y) Y^0.9811 / 1e-4``,
up to 1e4 times the pixel's ``Y``)."""

AUGMENTATION = dict(post_exposure=(-2.0, 2.0), temperature=(-40, 40), tint=(-40, 40), contrast=(-50, 50),
                    split_shadows=(0.3, 0.7), split_highlights=(0.3, 0.7),
                    split_balance=(-50, 50), hue_shift=(-180, 180), saturation=(-100, 100), bloom_threshold=(0.5, 2.0),
                    bloom_intensity=(0.0, 2.0), tonemap=["aces", "neutral_hdr", "unreal_filmic", "aces_reference"], p=0.8)
"""``RandomPostFX`` with every grade control, bloom and four tone mappers (the ACES 1 family and the HDR range
reduction), on a batch of four copies of the sweep (seeded draws)."""


def _look(path: Path) -> torch.nn.Module:
    return tg.PostFX.from_config(json.loads(path.read_text())).eval()


class _Drawn(torch.nn.Module):
    """``RandomPostFX`` drawing the same looks at every call (a fixed generator), so float64 sees float32's draws."""

    def __init__(self):
        super().__init__()
        self.augmentation = tg.RandomPostFX(**AUGMENTATION)

    def forward(self, image):
        return self.augmentation(image.expand(4, -1, -1, -1), generator=torch.Generator().manual_seed(0))


CASES = {**{name: kind.example for name, kind in STAGE_KINDS.items()},
         **{f"look-{path.stem}": functools.partial(_look, path) for path in LOOKS}, "random-postfx": _Drawn}


def _gradients(name: str, image: torch.Tensor, bound: bool = False) -> dict:
    """The sum of ``name``'s output on ``image``: the output's magnitude and the gradients, of the image and of every
    learnable control; ``bound`` the output to a half's range (what a float16 or bfloat16 input gets back)."""
    module = CASES[name]()
    controls = learnable(module)
    module = module.to(image.dtype) if image.dtype == torch.float64 else module
    image = image.clone().requires_grad_()
    out = module(image)
    assert torch.isfinite(out).all(), f"{name}: {(~torch.isfinite(out)).sum().item()} non-finite outputs"
    out = out.clamp(-HALF_MAX, HALF_MAX) if bound else out
    out.double().sum().backward()
    return {"output": out.detach().double().abs().sum(), "image": image.grad,
            **{control: value.grad for control, value in controls.items() if value.grad is not None}}


@functools.lru_cache(maxsize=None)
def _float64(name: str, dtype: torch.dtype) -> dict:
    return _gradients(name, sweep_frame(dtype).double(), bound=dtype != torch.float32)


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("dtype", DTYPES, ids=str)
@pytest.mark.parametrize("name", list(CASES))
def test_every_gradient_on_the_sweep_is_finite_and_bounded_by_float64s(name, dtype, form, monkeypatch):
    exact = _float64(name, dtype)
    if form == "compiled":
        monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    got = _gradients(name, sweep_frame(dtype))
    assert got.keys() == exact.keys()
    for what, gradient in got.items():
        if what == "output":
            continue
        gradient = gradient.double()
        assert torch.isfinite(gradient).all(), f"{name} {form}: {(~torch.isfinite(gradient)).sum().item()} non-finite gradients of {what}"
        largest, bound = gradient.abs().max(), GROWTH * exact[what].abs().max() + ROUNDING * exact["output"]
        assert largest <= bound, f"{name} {form}: the gradient of {what} reaches {largest:.3g}, float64's bound {bound:.3g}"
    assert got["image"].abs().max() <= IMAGE_BOUND and exact["image"].abs().max() <= IMAGE_BOUND


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("dtype", DTYPES, ids=str)
@pytest.mark.parametrize("mode", TONEMAP_MODES)
def test_every_tone_mappers_gradient_near_black_keeps_its_bound(mode, dtype, form, monkeypatch):
    if form == "compiled":
        monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    image = sweep_frame(dtype).requires_grad_()
    tg.ToneMap(mode)(image).float().sum().backward()
    near_black = image.detach().abs().amax(1, keepdim=True).expand_as(image) <= NEAR_BLACK
    assert image.grad.float()[near_black].abs().max() < NEAR_BLACK_BOUND


def test_the_float64_bound_near_black_is_acess_own():
    """The bound is the curves' own: float64's largest derivative near black, over every tone mapper, lies within a
    factor of 2 below it (ACES's dim-surround floors), and float32 denormals gave ACES NaN there before."""
    image = sweep_frame(torch.float32).double().requires_grad_()
    near_black = (image.detach().abs().amax(1, keepdim=True) <= NEAR_BLACK).expand_as(image)
    largest = {}
    for mode in TONEMAP_MODES:
        image.grad = None
        tg.ToneMap(mode).double()(image).sum().backward()
        largest[mode] = image.grad[near_black].abs().max().item()
    assert max(largest, key=largest.get) == "aces" and NEAR_BLACK_BOUND / 2 < largest["aces"] < NEAR_BLACK_BOUND
