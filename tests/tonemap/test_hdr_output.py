"""HDR output: Unity's Neutral HDR mapping against BT.2390 / Unity's formulas written with colour-science's
ICtCp, the display encodings against colour-science, and the display target through PostFX, ONNX and the CLI."""

import struct
import warnings
import zlib

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.shots.outputs import write_frame
from torchgrade.output.display import encode_display
from torchgrade.functional import tonemap
from torchgrade.tonemap import bt2390_eetf

from reference.pixels import pixels, rows
from reference.tonemap import hdr_samples, ref_bt2390_pq, ref_neutral_hdr

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

SETTINGS = [dict(), dict(range_reduction="reinhard"), dict(hue_shift=0.4, peak_luminance=600.0, paper_white=100.0),
            dict(range_reduction="reinhard", hue_shift=1.0, peak_luminance=4000.0, min_luminance=0.0)]
REFERENCE_NAMES = {"range_reduction": "method", "peak_luminance": "peak", "min_luminance": "min_nits"}


@pytest.mark.parametrize("settings", SETTINGS)
def test_neutral_hdr_matches_unity_formulas(settings, device):
    rgb = hdr_samples()
    ours = rows(tonemap(pixels(rgb, device=device), "neutral_hdr", **settings))
    expected = ref_neutral_hdr(rgb, **{REFERENCE_NAMES.get(k, k): v for k, v in settings.items()})
    np.testing.assert_allclose(ours, expected, atol=1e-9)


def test_bt2390_eetf_invariants():
    nits = torch.from_numpy(np.geomspace(1e-3, 1e5, 500))
    out = bt2390_eetf(nits, 0.0, 1000.0)
    knee_nits = colour.models.eotf_ST2084(1.5 * colour.models.eotf_inverse_ST2084(1000.0) - 0.5)
    below = (nits < knee_nits).numpy()
    # Below the knee only the black lift b (1 - E)^4 acts, b = PQ(0 cd/m²) = c1^m2 as Unity computes it (L_B = 0).
    e_in, e_out = colour.models.eotf_inverse_ST2084(nits.numpy()), colour.models.eotf_inverse_ST2084(out.numpy())
    black = colour.models.eotf_inverse_ST2084(0.0)
    np.testing.assert_allclose(e_out[below], e_in[below] + black * (1 - e_in[below]) ** 4, atol=1e-12)
    assert out.diff().min() >= 0 and out.max() == pytest.approx(1000.0, rel=1e-6)  # monotone, 10000+ -> peak
    lifted = bt2390_eetf(torch.zeros(1, dtype=torch.float64), 0.05, 1000.0)
    assert float(lifted) == pytest.approx(0.05, rel=1e-3)  # black goes to the display's black
    e = np.linspace(0.01, 1.0, 100)
    np.testing.assert_allclose(colour.models.eotf_inverse_ST2084(bt2390_eetf(torch.from_numpy(colour.models.eotf_ST2084(e)), 0.1, 600.0).numpy()),
                               ref_bt2390_pq(e, 0.1, 600.0), atol=1e-9)


def test_neutral_hdr_greys_keep_their_colour_and_stay_below_peak():
    grey = torch.logspace(-4, 4, 300, dtype=torch.float64).reshape(1, 1, 1, -1).expand(1, 3, 1, -1)
    out = tonemap(grey, "neutral_hdr")[0, :, 0]
    assert (out[0] - out[2]).abs().max() < 1e-9 and out.max() <= 1.0 and out[1].diff().min() >= 0


def test_neutral_hdr_gradients_are_finite_at_extremes():
    image = torch.tensor([0.0, 1e-30, -1.0, 0.18, 60.0, 65504.0]).reshape(1, 1, 2, 3).expand(1, 3, 2, 3).clone().requires_grad_()
    peak = torch.tensor(800.0, requires_grad=True)
    tg.ToneMap("neutral_hdr", peak_luminance=peak, hue_shift=0.5)(image).sum().backward()
    assert torch.isfinite(image.grad).all() and torch.isfinite(peak.grad)


NITS = np.concatenate([[0.0], np.geomspace(1e-3, 1.0, 200)])


def test_pq_and_primaries_match_colour_science(device):
    rgb = np.stack([NITS, NITS[::-1], np.sqrt(NITS)], 1)
    ours = rows(tg.Display("pq", "rec2020", 1000.0).to(device)(pixels(rgb, device=device)))
    to_2020 = colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES["ITU-R BT.709"], colour.RGB_COLOURSPACES["ITU-R BT.2020"])
    expected = colour.models.eotf_inverse_ST2084(np.clip(rgb @ to_2020.T, 0, 1) * 1000.0)
    np.testing.assert_allclose(ours, expected, atol=1e-9)


@pytest.mark.parametrize("peak", [400.0, 1000.0, 2000.0])
def test_hlg_matches_colour_science(peak, device):
    rgb = np.stack([NITS, NITS[::-1], np.sqrt(NITS)], 1)
    ours = rows(encode_display(pixels(rgb, device=device), "hlg", "rec2020", peak, input_primaries="rec2020"))
    # Saturated peak colours need scene light above 1 (a signal above 1); the display range ends at 1.
    expected = np.clip(colour.models.eotf_inverse_BT2100_HLG(rgb * peak, L_B=0.0, L_W=peak), 0.0, 1.0)
    np.testing.assert_allclose(ours, expected, atol=1e-6)


def test_srgb_and_bt1886_match_colour_science():
    rgb = np.stack([NITS] * 3, 1)
    np.testing.assert_allclose(rows(encode_display(pixels(rgb), "srgb")), colour.models.eotf_inverse_sRGB(rgb), atol=1e-9)
    np.testing.assert_allclose(rows(encode_display(pixels(rgb), "bt1886")), colour.models.eotf_inverse_BT1886(rgb), atol=1e-9)


def test_postfx_carries_the_hdr_tone_mappers_peak_and_primaries():
    look = tg.PostFX(tonemap={"mode": "neutral_hdr", "peak_luminance": 600.0}, display="hdr_pq")
    assert look.display.to_config() == {"encoding": "pq", "primaries": "rec2020", "peak_luminance": 600.0, "input_primaries": "rec2020"}
    image = torch.rand(1, 3, 4, 5, dtype=torch.float64) * 20
    expected = tg.color.linear_to_pq(tonemap(image, "neutral_hdr", peak_luminance=600.0), reference=600.0)
    torch.testing.assert_close(look(image), expected)
    assert tg.PostFX.from_config(look.to_config()).to_config() == look.to_config()


def test_sdr_look_encoded_as_pq_puts_white_at_100_nits():
    look = tg.PostFX(tonemap="none", display="hdr_pq")
    out = look(torch.ones(1, 3, 1, 1, dtype=torch.float64))
    assert float(out[0, 0, 0, 0]) == pytest.approx(colour.models.eotf_inverse_ST2084(100.0), abs=1e-9)


def test_display_linear_in_the_same_primaries_is_not_built():
    assert tg.PostFX(tonemap="aces", display="linear").stages().keys() == {"tonemap"}


def test_exported_look_carries_the_display_encoding(tmp_path):
    look = tg.PostFX(tonemap={"mode": "neutral_hdr"}, display="hdr_pq")
    path = tmp_path / "hdr.onnx"
    tg.onnx.export(look, path)
    assert tg.onnx.verify(look, path, torch.rand(1, 3, 9, 11) * 30) <= 1e-4


def _read_png16(path) -> np.ndarray:
    """RGB 16-bit PNG decoded from its chunks (PNG spec: IHDR, IDAT, filter type 0 rows)."""
    data, chunks, at = path.read_bytes(), {}, 8
    while at < len(data):
        (length,), kind = struct.unpack(">I", data[at : at + 4]), data[at + 4 : at + 8]
        chunks[kind] = chunks.get(kind, b"") + data[at + 8 : at + 8 + length]
        at += 12 + length
    width, height, depth, colour_type = struct.unpack(">IIBB", chunks[b"IHDR"][:10])
    assert (depth, colour_type) == (16, 2)
    rows_ = np.frombuffer(zlib.decompress(chunks[b"IDAT"]), np.uint8).reshape(height, 1 + 6 * width)
    assert (rows_[:, 0] == 0).all()
    return rows_[:, 1:].copy().view(">u2").reshape(height, width, 3).astype(np.int64)


def test_png16_holds_the_signal_to_one_code(tmp_path):
    signal = torch.rand(3, 5, 7, dtype=torch.float64)
    write_frame(tmp_path / "s.png", signal, "16", encoded=True)
    codes = _read_png16(tmp_path / "s.png")
    assert np.abs(codes - signal.permute(1, 2, 0).numpy() * 65535).max() <= 0.5


def test_grade_cli_writes_pq_png16_and_exr(tmp_path):
    from torchgrade.cli import main
    from torchgrade.io import read_exr, write_exr

    source = tmp_path / "in.exr"
    write_exr(source, torch.rand(3, 6, 8) * 8)
    assert main(["grade", str(source), "-o", str(tmp_path / "o.png"), "--tonemap", "neutral_hdr", "--display", "hdr_pq", "--bit-depth", "16"]) == 0
    assert main(["grade", str(source), "-o", str(tmp_path / "o.exr"), "--tonemap", "neutral_hdr", "--display", "hdr_pq"]) == 0
    png, exr = _read_png16(tmp_path / "o.png") / 65535.0, read_exr(tmp_path / "o.exr").permute(1, 2, 0).numpy()
    assert np.abs(png - exr).max() <= 1e-3 and 0.0 < exr.max() <= 0.76  # PQ codes of at most 1000 cd/m²
