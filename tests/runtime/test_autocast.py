"""The maths runs in float32 (or the input's higher precision) whatever ``torch.autocast`` is active.

Under autocast a float32 image must give the float32 result: autocast would otherwise run the
colour matrices in bfloat16/float16 (43 8-bit codes off on Desk before the fix). The bounds are the
README's for float16/bfloat16 *inputs* (1e-3 and 8e-3 in display values), which autocast must not
exceed since it changes no input; low-precision inputs keep their dtype.
"""

from __future__ import annotations

import pytest
import torch

import torchgrade as tg
from torchgrade.lut import identity_table

BFLOAT16_DISPLAY_BOUND = 8e-3
FLOAT16_DISPLAY_BOUND = 1e-3


def _codes(display: torch.Tensor) -> torch.Tensor:
    """8-bit sRGB code values of display-referred linear values (the error unit the README reports)."""
    return tg.color.linear_to_srgb(display.double().clamp(0.0, 1.0)) * 255.0


@pytest.fixture(scope="module")
def desk(exr_dir):
    """A 96x96 crop of Desk (bright lamp and dark wood), as (1, 3, H, W) float32."""
    image = tg.io.read_exr(exr_dir / "Desk.exr")[:3]
    return image[:, 100:196, 150:246].unsqueeze(0).contiguous()


def _look():
    return torch.nn.Sequential(tg.ColorGrade(contrast=20, saturation=10, aces=True), tg.ToneMap("aces"))


def test_grade_and_aces_under_cpu_bfloat16_autocast_match_float32(desk):
    look = _look()
    reference = look(desk)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = look(desk)
    assert out.dtype == torch.float32
    assert (out - reference).abs().max() <= BFLOAT16_DISPLAY_BOUND
    assert (_codes(out) - _codes(reference)).abs().max() < 0.5, "autocast changed an 8-bit code"


def _modules():
    return {
        "tonemap": tg.ToneMap("aces"),
        "grade": tg.ColorGrade(contrast=30, temperature=20, channel_mixer=((1.2, -0.1, -0.1), (0.0, 1.0, 0.0), (0.1, 0.0, 0.9))),
        "primary": tg.PrimaryGrade("log", contrast=(1.3, 1.2, 1.1), gamma=(0.8, 0.9, 1.0)),
        "bloom": tg.Bloom(threshold=0.8, intensity=0.5),
        "convolution-bloom": tg.ConvolutionBloom(torch.rand(1, 7, 7), intensity=0.5),
        "exposure": tg.AutoExposure(),
        "dither": tg.Dither(),
        "lut": tg.LUT3D(identity_table(9) ** 1.5),
    }


NEEDS_CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="device-conditional: needs CUDA for CUDA autocast")
AUTOCASTS = [("cpu", torch.bfloat16), pytest.param("cuda", torch.float16, marks=NEEDS_CUDA)]


@pytest.mark.parametrize("device, dtype", AUTOCASTS)
@pytest.mark.parametrize("name", list(_modules()))
def test_every_stage_ignores_autocast(desk, name, device, dtype):
    module = _modules()[name].to(device)
    image = (desk.clamp(0.0, 1.0) if name == "lut" else desk).to(device)
    reference = module(image)
    with torch.autocast(device, dtype=dtype):
        out = module(image)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, reference, rtol=1e-6, atol=1e-6)


def test_low_precision_input_under_autocast_keeps_its_dtype_within_the_readme_bound(desk):
    look = _look()
    quantised = desk.to(torch.bfloat16)
    reference = look(quantised.float())
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = look(quantised)
    assert out.dtype == torch.bfloat16
    assert (out.float() - reference).abs().max() <= BFLOAT16_DISPLAY_BOUND


@NEEDS_CUDA
def test_grade_and_aces_under_cuda_float16_autocast_match_float32(desk):
    look, image = _look().cuda(), desk.cuda()
    reference = look(image)
    with torch.autocast("cuda", dtype=torch.float16):
        out = look(image)
    assert out.dtype == torch.float32
    assert (out - reference).abs().max() <= FLOAT16_DISPLAY_BOUND


@pytest.mark.parametrize("device, dtype", AUTOCASTS)
@pytest.mark.parametrize("name", list(_modules()))
def test_every_stage_is_captured_whole_under_autocast(desk, name, device, dtype):
    """Under an active autocast the whole forward is one graph (``fullgraph=True``; Dynamo alone, the capture is what
    can break) that gives what it gives without autocast (the compiled forms differ from eager in float32 rounding)."""
    torch.compiler.reset()
    module = torch.compile(_modules()[name].eval().to(device), fullgraph=True, backend="eager")
    _assert_autocast_changes_nothing(module, (desk.clamp(0.0, 1.0) if name == "lut" else desk).to(device), dtype)


@pytest.mark.parametrize("device, dtype", AUTOCASTS)
def test_a_compiled_look_under_autocast_matches_float32(desk, device, dtype):
    """``tg.compile`` (Inductor; CUDA graphs on CUDA) of a grade and ACES under autocast: the float32 result."""
    torch.compiler.reset()
    _assert_autocast_changes_nothing(tg.compile(_look().eval().to(device)), desk.to(device), dtype)


def _assert_autocast_changes_nothing(compiled, image, dtype):
    """``compiled`` gives, under ``dtype`` autocast on the image's device, the float32 result it gives without."""
    with torch.no_grad():
        reference = compiled(image).clone()  # a CUDA graph's output is overwritten by its next call
        with torch.autocast(image.device.type, dtype=dtype):
            out = compiled(image)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, reference, rtol=1e-6, atol=1e-6)


DEEP_BATCH = (16, 3, 131, 197)
"""A batch of 16 at odd sides whose bloom pyramid is 5 levels deep: a sum over a level of this size would pass
float16's range (65504) at the scene values below, where a mean does not."""


def _deep_batch() -> torch.Tensor:
    generator = torch.Generator().manual_seed(3)
    batch = torch.rand(DEEP_BATCH, generator=generator) ** 3 * 60.0
    batch[..., ::17, ::19] = 5000.0
    return batch


def _catalogue():
    from torchgrade.testing.catalog import STAGE_KINDS

    kinds = {name: kind.example for name, kind in STAGE_KINDS.items()}
    kinds["randompostfx"] = lambda: tg.RandomPostFX(post_exposure=(-1, 1), contrast=(-30, 30), saturation=(-30, 30),
                                                    hue_shift=(-20, 20), bloom_intensity=(0, 0.5), tonemap=["aces", "neutral"],
                                                    p=0.8)
    kinds["randompostfx-no-tonemap"] = lambda: tg.RandomPostFX(bloom_intensity=(0, 1), contrast=(-30, 30), p=0.8)
    return kinds


AUTOCASTS_BOTH = [("cpu", torch.float16), ("cpu", torch.bfloat16), pytest.param("cuda", torch.float16, marks=NEEDS_CUDA),
                  pytest.param("cuda", torch.bfloat16, marks=NEEDS_CUDA)]


@pytest.mark.parametrize("device, dtype", AUTOCASTS_BOTH, ids=lambda v: str(v).replace("torch.", ""))
@pytest.mark.parametrize("name", list(_catalogue()))
def test_every_stage_of_the_catalogue_ignores_autocast_on_a_deep_batch(name, device, dtype):
    """Every stage kind (each mode of each stage), a whole look and ``RandomPostFX`` (one draw replayed) give under
    float16 and bfloat16 autocast what they give in float32, on a batch of 16 with scene values up to 5000 and a
    5-level pyramid (before bloom's levels held means, a look's float16 pyramid overflowed at 128²)."""
    module = _catalogue()[name]().eval().to(device)
    batch = _deep_batch().to(device)
    if name.startswith(("lut", "look-lut", "dither")):
        batch = batch.clamp(0.0, 1.0)
    arguments = {}
    if name.startswith("randompostfx"):
        arguments["params"] = module.sample_params(batch.shape[0], torch.Generator().manual_seed(4), device)
    with torch.no_grad():
        reference = module(batch, **arguments)
        with torch.autocast(device, dtype=dtype):
            out = module(batch, **arguments)
    assert out.dtype == torch.float32 and out.isfinite().all()
    torch.testing.assert_close(out, reference, rtol=1e-6, atol=1e-6)
