"""Display encodings and primaries of torchgrade.color (PQ, HLG, ACEScct, Rec.2020, Display P3)
against colour-science, plus gradients at the extremes."""

import warnings

import numpy as np
import pytest
import torch

from torchgrade import color

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

NITS = np.concatenate(([0.0, 1e-6, 0.005], np.geomspace(0.01, 10000.0, 400)))
CODES = np.linspace(0.0, 1.0, 501)


def test_pq_matches_colour_science_both_ways():
    encoded = color.linear_to_pq(torch.from_numpy(NITS), reference=1.0)
    np.testing.assert_allclose(encoded.numpy(), colour.models.eotf_inverse_ST2084(NITS), atol=1e-12)
    decoded = color.pq_to_linear(torch.from_numpy(CODES), reference=1.0)
    np.testing.assert_allclose(decoded.numpy(), colour.models.eotf_ST2084(CODES), rtol=1e-10, atol=1e-10)


def test_pq_reference_scales_the_input_in_nits():
    scene = torch.from_numpy(NITS / 100.0)
    np.testing.assert_allclose(color.linear_to_pq(scene).numpy(), colour.models.eotf_inverse_ST2084(NITS), atol=1e-12)
    display = torch.from_numpy(NITS / 1000.0)
    round_trip = color.pq_to_linear(color.linear_to_pq(display, reference=1000.0), reference=1000.0)
    np.testing.assert_allclose(round_trip.numpy(), display.numpy(), rtol=1e-9, atol=1e-12)


def test_hlg_matches_colour_science_both_ways():
    scene = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(color.hlg_oetf(torch.from_numpy(scene)).numpy(),
                               colour.models.oetf_BT2100_HLG(scene), atol=1e-9)
    np.testing.assert_allclose(color.hlg_inverse_oetf(torch.from_numpy(CODES)).numpy(),
                               colour.models.oetf_inverse_BT2100_HLG(CODES), atol=1e-7)


def test_acescct_matches_colour_science_both_ways():
    linear = np.concatenate(([0.0, 0.001, 0.0078125, 0.18, 1.0], np.geomspace(1e-4, 65504.0, 300)))
    np.testing.assert_allclose(color.linear_to_acescct(torch.from_numpy(linear)).numpy(),
                               colour.models.log_encoding_ACEScct(linear), atol=1e-12)
    codes = np.linspace(0.0, color.linear_to_acescct(torch.tensor(65504.0, dtype=torch.float64)).item(), 400)
    np.testing.assert_allclose(color.acescct_to_linear(torch.from_numpy(codes)).numpy(),
                               colour.models.log_decoding_ACEScct(codes), rtol=1e-10, atol=1e-12)


def test_acescct_saturates_at_half_max_like_acescc():
    assert color.acescct_to_linear(torch.tensor(3.0, dtype=torch.float64)).item() == pytest.approx(65504.0)


@pytest.mark.parametrize("name, space", [("rec709_to_rec2020", "ITU-R BT.2020"), ("rec709_to_p3", "Display P3")])
def test_primaries_matrices_match_colour_science(name, space):
    # BT.709 rather than sRGB: colour-science's sRGB carries IEC 61966-2-1's rounded matrix.
    expected = colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES["ITU-R BT.709"], colour.RGB_COLOURSPACES[space])
    np.testing.assert_allclose(color.MATRICES[name].numpy(), expected, atol=2e-7)
    inverse = name.split("_to_")[1] + "_to_rec709"
    np.testing.assert_allclose((color.MATRICES[inverse] @ color.MATRICES[name]).numpy(), np.eye(3), atol=1e-12)


@pytest.mark.parametrize("fn", [color.linear_to_pq, color.pq_to_linear, color.hlg_oetf, color.hlg_inverse_oetf,
                                color.linear_to_acescct, color.acescct_to_linear])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_encodings_have_finite_values_and_gradients_at_extremes(fn, dtype, device):
    tiny = torch.finfo(dtype).tiny
    x = torch.tensor([-1.0, -tiny, 0.0, tiny / 4, tiny, 1e-8, 0.5, 1.0, 60.0, 65504.0], dtype=dtype, device=device, requires_grad=True)
    y = fn(x)
    (grad,) = torch.autograd.grad(y.sum(), x)
    assert torch.isfinite(y).all() and torch.isfinite(grad).all()


def test_encodings_pass_gradcheck():
    x = torch.tensor([0.002, 0.05, 0.3, 0.7, 0.95], dtype=torch.float64, requires_grad=True)
    for fn in (color.linear_to_pq, color.pq_to_linear, color.hlg_oetf, color.hlg_inverse_oetf,
               color.linear_to_acescct, color.acescct_to_linear):
        assert torch.autograd.gradcheck(fn, (x,))


def test_public_names_are_declared():
    assert {"linear_to_pq", "pq_to_linear", "hlg_oetf", "hlg_inverse_oetf", "linear_to_acescct",
            "acescct_to_linear", "REC2020_CHROMATICITIES", "P3_D65_CHROMATICITIES"} <= set(color.__all__)
    assert all(hasattr(color, name) for name in color.__all__)
