"""aces_reference (ACES 1.0.3 RRT + ODT 100 nits dim) against OpenColorIO's builtin ACES 1.x SDR video
transform on the sample images, out-of-gamut and very bright pixels included."""

import functools

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.functional import tonemap
from torchgrade.io import read_exr

ocio = pytest.importorskip("PyOpenColorIO")

IMAGES = ("BrightRings", "CandleGlass", "Carrots", "Desk", "Garden", "GoldenGate", "WideColorGamut", "WideFloatRange")
PIXELS_PER_IMAGE = 2000
CONFIG = "studio-config-v2.2.0_aces-v1.3_ocio-v2.4"
# The view is the builtin "ACES-OUTPUT - ACES2065-1_to_CIE-XYZ-D65 - SDR-VIDEO_1.0"; the display adds the encoding.
DISPLAYS = {"srgb": "sRGB - Display", "bt1886": "Rec.1886 Rec.709 - Display"}


@functools.lru_cache(maxsize=None)
def _processor(display: str):
    config = ocio.Config.CreateFromBuiltinConfig(CONFIG)
    return config.getProcessor("Linear Rec.709 (sRGB)", display, "ACES 1.0 - SDR Video", ocio.TRANSFORM_DIR_FORWARD).getDefaultCPUProcessor()


def _ocio(rgb: np.ndarray, encoding: str) -> np.ndarray:
    out = np.array(rgb, dtype=np.float32, order="C", copy=True)
    _processor(DISPLAYS[encoding]).applyRGB(out)
    return np.clip(out, 0.0, 1.0)  # the ODT clips to the display range; OpenColorIO's encodings do not


def _ours(rgb: np.ndarray, encoding: str, dtype=torch.float32) -> np.ndarray:
    image = torch.from_numpy(np.ascontiguousarray(rgb.T)).to(dtype)[None, :, :, None]
    linear = tonemap(image, "aces_reference")
    encoded = tg.color.linear_to_srgb(linear) if encoding == "srgb" else linear ** (1.0 / 2.4)  # BT.1886 with a black of 0
    return encoded[0, :, :, 0].T.double().numpy()


@functools.lru_cache(maxsize=None)
def _sample(exr_dir, name: str) -> np.ndarray:
    """Finite pixels exposed so the median positive Rec.709 luminance is 0.18: the brightest, the most
    negative and a random draw (the full frames are measured by benchmarks/plot_tonemap.py)."""
    image = read_exr(exr_dir / f"{name}.exr", to_rec709=True)[:3].reshape(3, -1).T.double().numpy()
    image = image[np.isfinite(image).all(1)]
    y = image @ np.array([0.2126729, 0.7151522, 0.0721750])
    image = image * (0.18 / np.median(y[y > 0]))
    image = image[(np.abs(image) <= 65504.0).all(1)]
    rng = np.random.default_rng(sum(map(ord, name)))
    extremes = np.concatenate([np.argsort(image.max(1))[-100:], np.argsort(image.min(1))[:100]])
    drawn = rng.choice(len(image), size=min(PIXELS_PER_IMAGE, len(image)), replace=False)
    return image[np.concatenate([extremes, drawn])].astype(np.float32)


@pytest.mark.parametrize("encoding", sorted(DISPLAYS))
@pytest.mark.parametrize("name", IMAGES)
def test_matches_opencolorio_on_sample_images(exr_dir, name, encoding):
    pixels = _sample(exr_dir, name)
    codes = np.abs(_ours(pixels, encoding) - _ocio(pixels, encoding)) * 255.0
    assert codes.max() <= 0.5, (name, codes.max(), pixels[codes.max(1).argmax()])


def _out_of_gamut_and_bright(n: int = 3000) -> np.ndarray:
    """Colours over 2^-10..2^14 with a negative component in a quarter of them, plus the pixels that
    a clamp at 0 or at 60 got wrong (CandleGlass's blue -0.128, a 200 red)."""
    rng = np.random.default_rng(11)
    rgb = np.exp2(rng.uniform(-10, 14, (n, 3))) * rng.choice([1.0, 1.0, 1.0, -0.1], (n, 3))
    known = [(1.7636149, 1.1893996, -0.12810919), (200.0, 0.5, 0.5), (1e4, 1.0, 1.0), (-0.14, -0.096, 3.86), (0.0, 140.3, 0.0)]
    return np.concatenate([rgb, known]).astype(np.float32)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_matches_opencolorio_out_of_gamut_and_above_60(dtype):
    rgb = _out_of_gamut_and_bright()
    codes = np.abs(_ours(rgb, "srgb", dtype) - _ocio(rgb, "srgb")) * 255.0
    assert codes.max() <= 0.5, (codes.max(), rgb[codes.max(1).argmax()])


def test_keeps_rising_above_60_as_the_ctl_does():
    # The RRT spline saturates at 0.18 * 2^18 (~47000); a ceiling at 60 flattened everything above 60.
    grey = torch.tensor([60.0, 200.0, 2000.0], dtype=torch.float64).reshape(1, 1, 1, 3).expand(1, 3, 1, 3)
    out = tonemap(grey, "aces_reference", clip=False)[0, 1, 0]
    assert out[0] < out[1] < out[2]


def test_gradients_are_finite_for_negative_and_huge_inputs():
    rgb = torch.tensor(_out_of_gamut_and_bright(200).T, dtype=torch.float32)[None, :, :, None]
    rgb = torch.cat([rgb, torch.tensor([-65504.0, 65504.0, -1e-30]).reshape(1, 3, 1, 1)], dim=2).requires_grad_()
    tonemap(rgb, "aces_reference").sum().backward()
    assert torch.isfinite(rgb.grad).all()
