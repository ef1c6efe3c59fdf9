"""The forms a compiler is given, run eagerly: per-pixel chains on planes (``planes=True``, what
:func:`~torchgrade.runtime.strips.pixelwise` passes a stage while compiling), the ACES 2.0 tables gathered a row at a
time. Against the float64 reference and OpenColorIO, and against the frame forms on hostile values, in outputs and
gradients. (That Inductor fuses them: ``tests/runtime/test_gpu_path.py``.)"""

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.tonemap.aces2 import aces2_output
from torchgrade.tonemap.registry import tone_mapped

from reference.compiled import as_compiled, outputs_and_gradients
from reference.pixels import EXTREMES, pixels, rows
from reference.tonemap import REFERENCES, hdr_samples

HOSTILE = [float("nan"), float("inf"), -float("inf"), -1e30, -1.0, -1e-30, 1e-40, *EXTREMES]
ACES2_TARGETS = {
    "sdr": {"encoding": "bt1886"},
    "hdr_p3": {"peak_luminance": 1000.0, "limiting_primaries": "p3_d65", "display_primaries": "rec2020", "encoding": "pq"},
    "hdr_2020_from_aces": {"peak_luminance": 1000.0, "limiting_primaries": "rec2020", "input_space": "aces"},
}
"""The branches of the transform: SDR, a limiting gamut in another container (its matrix), a peak's scaling on
display-linear values, ACES2065-1 input."""


def hostile_pixels(dtype=torch.float64):
    """Every pair of the hostile values as red and green, blue at 0.18."""
    return pixels(np.array([(r, g, 0.18) for r in HOSTILE for g in HOSTILE]), dtype=dtype)


def test_aces_as_compiled_matches_the_independent_float64_formula(monkeypatch):
    as_compiled(monkeypatch)
    rgb = hdr_samples()
    np.testing.assert_allclose(rows(tg.ToneMap("aces")(pixels(rgb))), REFERENCES["aces"](rgb), atol=1e-9)


@pytest.mark.parametrize("name", ["aces", *ACES2_TARGETS])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_on_planes_equals_the_frame_form_on_hostile_values_in_outputs_and_gradients(name, dtype):
    """float64 to rounding; float32 to its rounding: outputs within 2e-5 (0.005 8-bit codes of a display value; 7e-6
    measured), gradients within 2e-3 relative, which the steep curves near black reach (ACES 2.0's gradients reach 30
    there; 6.4e-4 measured). A neutral pixel's gradient is left out of the comparison: ACES 2.0 is not differentiable
    there (its chroma is a cone, ``M = |(a, b)|``, and each form picks the hue its own rounding leaves; float64 forms
    differ by 1.4e-2 there), only finite."""
    def function(x, planes):
        return tone_mapped(x, "aces", planes=planes) if name == "aces" else aces2_output(x, planes=planes, **ACES2_TARGETS[name])

    image = hostile_pixels(dtype)
    eager_out, eager_gradient = outputs_and_gradients(lambda x: function(x, False), image)
    out, gradient = outputs_and_gradients(lambda x: function(x, True), image)
    assert torch.isfinite(out).all() and torch.isfinite(gradient).all()
    chromatic = (image != image[:, :1]).any(dim=1, keepdim=True).expand_as(image)
    single = dtype == torch.float32
    torch.testing.assert_close(out, eager_out, rtol=1e-4 if single else 1e-9, atol=2e-5 if single else 1e-12)
    torch.testing.assert_close(gradient[chromatic], eager_gradient[chromatic], rtol=2e-3 if single else 1e-9,
                               atol=1e-5 if single else 1e-12)


@pytest.mark.parametrize("name", ["aces", "aces2"])
def test_as_compiled_keeps_batches_and_unbatched_images(monkeypatch, name):
    batch = torch.rand(2, 3, 4, 5, dtype=torch.float64, generator=torch.Generator().manual_seed(2)) * 8
    stage = tg.ToneMap(name)
    eager_batch, eager_image = stage(batch), stage(batch[1])
    as_compiled(monkeypatch)
    torch.testing.assert_close(stage(batch), eager_batch, rtol=1e-9, atol=1e-12)
    torch.testing.assert_close(stage(batch[1]), eager_image, rtol=1e-9, atol=1e-12)


def test_aces2_on_planes_matches_opencolorio_out_of_gamut():
    from test_aces2 import TARGETS, _display, _ocio, _ours, _random_aces  # skips without OpenColorIO

    for display, view, kwargs, codes in TARGETS.values():
        aces = _random_aces(2000, 5)
        reference = _display(_ocio("ACES2065-1", display, view, aces))
        ours = _ours(aces, input_space="aces", encoding="bt1886" if codes == 255 else "pq", planes=True, **kwargs)
        distance = np.abs(ours - reference) * codes
        assert np.percentile(distance, 99.9) <= 0.5 and distance.max() <= 2.0, view


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
@pytest.mark.parametrize("name", ["aces", "grade"])
def test_as_compiled_half_precision_frames_are_computed_in_float32_as_eager(monkeypatch, name, dtype):
    """Both forms compute a float16/bfloat16 frame in float32 and round it back once: the same values to one step of
    the frame's dtype (the dtype's own tolerances), at its extremes too (65504 is float16's largest)."""
    import torchgrade as tg

    values = torch.tensor([0.0, 1e-4, 0.18, 1.0, 60.0, 65504.0]).to(dtype)
    image = torch.stack((values, values.roll(1), values.roll(3)))[None, :, :, None]
    stage = tg.ToneMap("aces") if name == "aces" else tg.ColorGrade(aces=True, contrast=30, saturation=20,
                                                                     split_shadows=(0.4, 0.5, 0.6))
    eager = stage(image)
    as_compiled(monkeypatch)
    compiled = stage(image)
    assert compiled.dtype == dtype and torch.isfinite(compiled).all()
    torch.testing.assert_close(compiled, eager)
