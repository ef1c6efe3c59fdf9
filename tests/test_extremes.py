"""Numerical stability of every public module at the extremes of its input.

Input families: all 65,536 half values (AllHalfValues.exr: NaN, ±Inf, denormals, negatives),
WideFloatRange.exr (±1e38), WideColorGamut.exr (negative out-of-gamut RGB), a grid of per-channel
values {0, 1e-45, 1e-38, 1e-8, 0.18, 1, 59.9, 60, 1e3, 65504, 1e30, 3e38}, and all-black and
all-constant frames. Every output must be finite (tone-mapped outputs inside [0, 1]) and every
gradient finite for finite inputs, computed in float64.
"""

import itertools

import pytest
import torch

import torchgrade as tg

GRID_VALUES = [0.0, 1e-45, 1e-38, 1e-8, 0.18, 1.0, 59.9, 60.0, 1e3, 65504.0, 1e30, 3e38]
STRONG_GRADE = dict(
    post_exposure=0.7, temperature=25, tint=-10, contrast=35, color_filter=(1.0, 0.9, 0.8),
    split_shadows=(0.3, 0.4, 0.7), split_highlights=(0.8, 0.6, 0.4), split_balance=15,
    channel_mixer=((1.1, -0.1, 0.0), (0.05, 0.9, 0.05), (0.0, 0.2, 0.8)), shadows=(0.9, 0.95, 1.1),
    midtones=(1.05, 1.0, 0.95), highlights=(1.1, 1.0, 0.9), hue_shift=25, saturation=30,
)


class _Lookup(torch.nn.Module):
    """A LUT with a fixed interpolation, as a module of its own."""

    def __init__(self, lut, interpolation):
        super().__init__()
        self.lut, self.interpolation = lut, interpolation

    def forward(self, image):
        return self.lut(image, interpolation=self.interpolation)


_LUT = tg.bake_lut(torch.nn.Sequential(tg.ColorGrade(**STRONG_GRADE), tg.ToneMap("aces")), size=9)


def _modules():
    """(name, module factory, output is display-referred)."""
    modules = [(f"tonemap-{mode}", lambda mode=mode: tg.ToneMap(mode), True) for mode in tg.TONEMAP_MODES]
    modules += [
        ("grade-linear", lambda: tg.ColorGrade(**STRONG_GRADE), False),
        ("grade-aces", lambda: tg.ColorGrade(aces=True, **STRONG_GRADE), False),
        ("autoexposure-log", lambda: tg.AutoExposure(metering="log"), False),
        ("autoexposure-reinhard", lambda: tg.AutoExposure(metering="mean", operator="reinhard"), False),
        ("bloom-additive", lambda: tg.Bloom(intensity=0.8, threshold=0.8, downscale_limit=1), False),
        ("bloom-scattering", lambda: tg.Bloom(mode="scattering", intensity=0.8, downscale_limit=1, bicubic_upsampling=True), False),
        ("lut-trilinear", lambda: _Lookup(_LUT, "trilinear"), True),
        ("lut-tetrahedral", lambda: _Lookup(_LUT, "tetrahedral"), True),
        ("postfx", lambda: tg.PostFX(exposure={}, bloom={"mode": "scattering", "intensity": 0.5}, grade={"aces": True, **STRONG_GRADE}, tonemap="aces"), True),
    ]
    return modules


MODULES = _modules()


def _grid() -> torch.Tensor:
    pixels = torch.tensor(list(itertools.product(GRID_VALUES, repeat=3)), dtype=torch.float64)
    return pixels.T.reshape(1, 3, 36, 48)


def _exr(exr_dir, name, step):
    return tg.io.read_exr(exr_dir / name)[:3, ::step, ::step].unsqueeze(0).double()


def _families(exr_dir):
    return {
        "all-half-values": _exr(exr_dir, "AllHalfValues.exr", 1),
        "wide-float-range": _exr(exr_dir, "WideFloatRange.exr", 4),
        "wide-color-gamut": _exr(exr_dir, "WideColorGamut.exr", 4),
        "value-grid": _grid(),
        "black": torch.zeros(1, 3, 16, 16, dtype=torch.float64),
        "constant": torch.full((1, 3, 16, 16), 0.18, dtype=torch.float64),
        "constant-huge": torch.full((1, 3, 16, 16), 3e38, dtype=torch.float64),
    }


@pytest.fixture(scope="module")
def families(exr_dir):
    return _families(exr_dir)


@pytest.mark.parametrize("family", ["all-half-values", "wide-float-range", "wide-color-gamut", "value-grid", "black", "constant", "constant-huge"])
@pytest.mark.parametrize("name, make, display", MODULES, ids=[m[0] for m in MODULES])
def test_outputs_finite_and_gradients_finite(families, family, name, make, display):
    image = families[family]
    out = make()(image.float())
    assert torch.isfinite(out).all(), f"{name} on {family}: {(~torch.isfinite(out)).sum().item()} non-finite outputs"
    if display:
        assert out.min() >= 0 and out.max() <= 1
    finite = torch.where(torch.isfinite(image), image, torch.zeros_like(image)).requires_grad_()
    make().double()(finite).sum().backward()
    assert torch.isfinite(finite.grad).all(), f"{name} on {family}: non-finite gradients"


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
@pytest.mark.parametrize("name, make, display", MODULES, ids=[m[0] for m in MODULES])
def test_low_precision_outputs_are_finite_on_every_half_value(families, dtype, name, make, display):
    image = families["all-half-values"].to(dtype)
    out = make()(image)
    assert out.dtype == dtype and torch.isfinite(out).all()


def test_reinhard_in_half_precision_does_not_break_above_60():
    # The source documents clamp at 60 because c / (c + 1) in half precision loses c above ~60;
    # torchgrade computes in float32, so the curve keeps rising between 10 and 60 and stays below 1.
    values = torch.tensor([10.0, 30.0, 59.0, 60.0, 1000.0, 65504.0], dtype=torch.float16).reshape(1, 1, 1, -1).expand(1, 3, 1, -1)
    out = tg.ToneMap("reinhard")(values)[0, 0, 0].float()
    expected = torch.tensor([10 / 11, 30 / 31, 59 / 60, 60 / 61, 60 / 61, 60 / 61])
    torch.testing.assert_close(out, expected.half().float(), atol=0, rtol=0)
