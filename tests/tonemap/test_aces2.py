"""ACES 2.0 Output Transform against OpenColorIO's builtin ACES 2.0 views, plus formula invariants."""

import functools
import math

import numpy as np
import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

import torchgrade as tg
from torchgrade.tonemap.aces2 import aces2_output
from torchgrade.tonemap.aces2.tonescale import daniele_tonescale, tonescale_params
from torchgrade.tonemap.aces2 import transform
from torchgrade.tonemap.aces2.transform import _output
from torchgrade.io import read_exr

ocio = pytest.importorskip("PyOpenColorIO")

IMAGES = ("BrightRings", "CandleGlass", "Carrots", "Desk", "Garden", "GoldenGate", "WideColorGamut", "WideFloatRange")
PIXELS_PER_IMAGE = 1500
# OpenColorIO's ACES 2.0 builtins; the studio config pairs them with these displays.
CONFIG = "studio-config-v4.0.0_aces-v2.0_ocio-v2.5"
SDR = ("Rec.1886 Rec.709 - Display", "ACES 2.0 - SDR 100 nits (Rec.709)", dict(), 255)
HDR_2020 = ("Rec.2100-PQ - Display", "ACES 2.0 - HDR 1000 nits (Rec.2020)",
            dict(peak_luminance=1000.0, limiting_primaries="rec2020", display_primaries="rec2020"), 1023)
HDR_P3 = ("Rec.2100-PQ - Display", "ACES 2.0 - HDR 1000 nits (P3 D65)",
          dict(peak_luminance=1000.0, limiting_primaries="p3_d65", display_primaries="rec2020"), 1023)
TARGETS = {"sdr_rec709": SDR, "hdr1000_rec2020": HDR_2020, "hdr1000_p3": HDR_P3}


def _config():
    return ocio.Config.CreateFromBuiltinConfig(CONFIG)


def _ocio(source: str, display: str, view: str, rgb: np.ndarray) -> np.ndarray:
    """OpenColorIO's CPU processor on ``(N, 3)`` float32 pixels."""
    proc = _config().getProcessor(source, display, view, ocio.TRANSFORM_DIR_FORWARD).getDefaultCPUProcessor()
    out = np.array(rgb, dtype=np.float32, order="C", copy=True)  # applyRGB writes in place
    proc.applyRGB(out)
    return out


def _ours(rgb: np.ndarray, dtype=torch.float32, device=None, **kwargs) -> np.ndarray:
    image = torch.from_numpy(np.ascontiguousarray(rgb.T)).to(device, dtype)[None, :, :, None]
    return aces2_output(image, **kwargs)[0, :, :, 0].T.double().cpu().numpy()


@functools.lru_cache(maxsize=None)
def _sample(exr_dir, name: str) -> np.ndarray:
    """Pixels of one image exposed so the median of its positive Rec.709 luminances is 0.18.

    Pixels left beyond ±65504 (WideFloatRange spans ±1e38) fall under the library's sanitize
    policy, which OpenColorIO does not share; the extremes tests cover them.
    """
    image = read_exr(exr_dir / f"{name}.exr", to_rec709=True)[:3].reshape(3, -1).T.double().numpy()
    y = image @ np.array([0.2126729, 0.7151522, 0.0721750])
    image = image * (0.18 / np.median(y[y > 0]))
    image = image[(np.abs(image) <= 65504.0).all(1)]
    rng = np.random.default_rng(sum(map(ord, name)))
    return image[rng.choice(len(image), size=min(PIXELS_PER_IMAGE, len(image)), replace=False)].astype(np.float32)


def _display(ref: np.ndarray) -> np.ndarray:
    """OpenColorIO's display values clipped at code 0: it mirrors negatives through the encoding
    ("MIRROR NEGS"), which only P3-limited colours in a Rec.2020 container reach."""
    return np.clip(ref, 0.0, None)


def code_distance(exr_dir, name: str, target: str):
    """(max, p99.9) code-value distance to OpenColorIO for one image and target."""
    display, view, kwargs, codes = TARGETS[target]
    pixels = _sample(exr_dir, name)
    ref = _display(_ocio("Linear Rec.709 (sRGB)", display, view, pixels))
    encoding = "bt1886" if codes == 255 else "pq"
    d = np.abs(_ours(pixels, encoding=encoding, **kwargs) - ref) * codes
    return float(d.max()), float(np.percentile(d, 99.9))


@pytest.mark.parametrize("target", sorted(TARGETS))
@pytest.mark.parametrize("name", IMAGES)
def test_matches_opencolorio_views_on_sample_images(exr_dir, name, target):
    worst, p999 = code_distance(exr_dir, name, target)
    assert p999 <= 0.5 and worst <= 2.0, (name, target, worst, p999)


@pytest.mark.parametrize("mode, target", [("aces2", "sdr_rec709"), ("aces2_hdr", "hdr1000_p3")])
def test_tonemap_modes_are_the_opencolorio_views(exr_dir, mode, target, device):
    display, view, _, codes = TARGETS[target]
    pixels = _sample(exr_dir, "Desk")
    ref = _display(_ocio("Linear Rec.709 (sRGB)", display, view, pixels))
    image = torch.from_numpy(np.ascontiguousarray(pixels.T))[None, :, :, None]
    linear = tg.ToneMap(mode).to(device)(image.to(device))[0, :, :, 0].T.double().cpu()
    encoded = linear ** (1.0 / 2.4) if codes == 255 else tg.color.linear_to_pq(linear, reference=1000.0)
    distance = np.abs(encoded.numpy() - ref) * codes
    assert distance.max() <= 2.0 and np.percentile(distance, 99.9) <= 0.5


def _random_aces(n: int, seed: int) -> np.ndarray:
    """HDR colours over 2^-12..2^8 with saturated and negative (out-of-gamut) components."""
    rng = np.random.default_rng(seed)
    x = np.exp2(rng.uniform(-12, 8, (n, 3))) * rng.choice([1.0, 1.0, 1.0, -0.05], (n, 3))
    return x.astype(np.float32)


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_matches_opencolorio_on_aces_input_out_of_gamut(target, device):
    display, view, kwargs, codes = TARGETS[target]
    aces = _random_aces(4000, 1)
    ref = _display(_ocio("ACES2065-1", display, view, aces))
    d = np.abs(_ours(aces, device=device, input_space="aces", encoding="bt1886" if codes == 255 else "pq", **kwargs) - ref) * codes
    assert np.percentile(d, 99.9) <= 0.5 and d.max() <= 2.0


@pytest.mark.parametrize("peak", [500.0, 2000.0, 4000.0])
def test_peak_luminance_matches_the_other_hdr_views(peak):
    view = f"ACES 2.0 - HDR {int(peak)} nits (Rec.2020)"
    aces = _random_aces(1500, 4)
    ref = _display(_ocio("ACES2065-1", "Rec.2100-PQ - Display", view, aces))
    ours = _ours(aces, input_space="aces", encoding="pq", peak_luminance=peak, limiting_primaries="rec2020")
    d = np.abs(ours - ref) * 1023
    assert np.percentile(d, 99.9) <= 0.5 and d.max() <= 2.0


def test_float64_agrees_with_float32():
    aces = _random_aces(2000, 2)
    single = _ours(aces, input_space="aces")
    double = _ours(aces, torch.float64, input_space="aces")
    assert np.abs(single - double).max() * 255 < 0.05


def test_tonescale_reaches_peak_at_r_hit_and_lifts_grey_with_peak():
    # By construction (aces-core Tonescale): scene r_hit (x100 cd/m²) lands exactly on the peak;
    # 18% grey lands near 10 cd/m² at 100 nits (the grey solve uses the w = 1 curve, so not exactly
    # c_d = 10.013) and rises with the peak.
    greys = []
    for peak in (100.0, 1000.0, 4000.0):
        t = tonescale_params(peak)
        r_hit = 128.0 + 768.0 * math.log(peak / 100.0) / math.log(100.0)
        assert float(daniele_tonescale(torch.tensor(100.0 * r_hit, dtype=torch.float64), t)) == pytest.approx(peak)
        greys.append(float(daniele_tonescale(torch.tensor(18.0, dtype=torch.float64), t)))
    assert greys[0] == pytest.approx(10.013, rel=2e-3) and greys[0] < greys[1] < greys[2]


def test_white_and_black_are_neutral_and_limited():
    image = torch.tensor([0.0, 1.0, 1e4, 65504.0], dtype=torch.float64).expand(3, 4)[None, :, :, None]
    out = aces2_output(image, input_space="aces")
    assert torch.all(out[0, :, 0] == 0)
    assert torch.allclose(out[0, 0], out[0, 1], atol=1e-6) and torch.allclose(out[0, 1], out[0, 2], atol=1e-6)
    assert float(out.max()) <= 1.0 and float(out[0, 1, 2]) == pytest.approx(1.0)


def test_gradcheck_on_hdr_colours_out_of_gamut_included():
    torch.manual_seed(3)
    magnitude = torch.exp2(torch.empty(1, 3, 4, 2, dtype=torch.float64).uniform_(-6, 6))
    sign = torch.where(torch.rand(1, 3, 4, 2) < 0.15, -0.02, 1.0).double()
    image = (magnitude * sign).requires_grad_()
    assert torch.autograd.gradcheck(lambda x: aces2_output(x, encoding="bt1886"), (image,), eps=1e-7, atol=1e-5)
    assert torch.autograd.gradcheck(
        lambda x: aces2_output(x, 1000.0, "p3_d65", "rec2020", encoding="pq"), (image,), eps=1e-7, atol=1e-5)


@pytest.mark.parametrize("dtype", (torch.float32, torch.float64))
def test_extremes_give_finite_outputs_and_gradients(dtype, device):
    tiny = torch.finfo(dtype).tiny
    values = [0.0, tiny, tiny / 4, 1e-30, 0.18, 60.0, 65504.0, 1e30, -1e30, -0.5,
              float("nan"), float("inf"), -float("inf")]
    n = len(values)
    grid = torch.tensor(values, dtype=dtype, device=device)
    image = torch.stack((grid, grid.roll(1), grid.roll(5)))[None, :, :, None].clone().requires_grad_()
    for kwargs in (dict(encoding="bt1886"), dict(peak_luminance=1000.0, limiting_primaries="rec2020", encoding="pq")):
        out = aces2_output(image, **kwargs)
        assert out.shape == (1, 3, n, 1) and torch.isfinite(out).all()
        (grad,) = torch.autograd.grad(out.sum(), image)
        assert torch.isfinite(grad).all()


def test_non_finite_pixels_do_not_spread(device):
    image = torch.rand(1, 3, 4, 4, device=device) * 4
    bad = image.clone()
    bad[0, :, 1, 2] = torch.tensor([float("nan"), float("inf"), -float("inf")])
    keep = torch.ones(4, 4, dtype=torch.bool, device=device)
    keep[1, 2] = False
    assert torch.equal(aces2_output(image)[..., keep], aces2_output(bad)[..., keep])


def test_autocast_does_not_lower_the_precision():
    image = torch.exp2(torch.empty(1, 3, 8, 8).uniform_(-6, 6))
    with torch.autocast("cpu", dtype=torch.bfloat16):
        under = aces2_output(image, encoding="bt1886")
    assert under.dtype == torch.float32 and torch.equal(under, aces2_output(image, encoding="bt1886"))


def test_tables_are_cached_per_peak_and_primaries():
    assert _output(100.0, "rec709") is _output(100.0, "rec709")
    assert _output(100.0, "rec709") is not _output(100.0, "p3_d65")


class ValueReads(TorchDispatchMode):
    """Counts the values read back (``.item()``, ``.tolist()``, ``float()``): building tables reads, a forward must not."""

    def __init__(self):
        super().__init__()
        self.reads = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.reads += func is torch.ops.aten._local_scalar_dense.default
        return func(*args, **(kwargs or {}))


def test_a_stage_keeps_its_tables_however_many_other_peaks_are_built():
    stage = tg.ToneMap("aces2_hdr", peak_luminance=1000.0)
    image = torch.rand(1, 3, 4, 4) * 4
    expected = stage(image)
    for step in range(1, transform.MAX_BUILT + 2):
        tg.ToneMap("aces2_hdr", peak_luminance=1000.0 + step)  # built, then dropped with its stage
    with ValueReads() as counted:
        out = stage(image)
    assert counted.reads == 0  # no table rebuilt in the forward (a compiled forward cannot build them)
    assert torch.equal(out, expected)


def test_tables_no_stage_holds_are_dropped_beyond_the_most_recent():
    for step in range(transform.MAX_BUILT + 3):
        transform.prepare_output(2000.0 + step, "rec2020")
    held = {prepared.key for prepared in transform._HELD}
    assert len([key for key in transform._BUILT if key not in held]) <= transform.MAX_BUILT
    assert (2000.0 + transform.MAX_BUILT + 2, "rec2020") in transform._BUILT


def test_bad_arguments_raise_clear_errors():
    image = torch.rand(1, 3, 2, 2)
    with pytest.raises(ValueError, match="encoding"):
        aces2_output(image, encoding="srgb2")
    with pytest.raises(ValueError, match="peak_luminance"):
        aces2_output(image, peak_luminance=50.0)
    with pytest.raises(ValueError, match="limiting_primaries"):
        aces2_output(image, limiting_primaries="ap0")
    with pytest.raises(TypeError, match="peak_luminance"):
        aces2_output(image, peak_luminance=torch.tensor(1000.0, requires_grad=True))
    assert torch.equal(aces2_output(image, peak_luminance=torch.tensor(1000.0)), aces2_output(image, 1000.0))
    with pytest.raises(TypeError, match="float16"):
        aces2_output(image.half())
    with pytest.raises(ValueError, match="channel"):
        aces2_output(torch.rand(1, 4, 2, 2))
