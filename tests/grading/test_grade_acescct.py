"""ColorGrade(aces=True, log_space="acescct"): contrast in ACEScct against colour-science's ACEScct and invariants."""

import warnings

import numpy as np
import pytest
import torch

import torchgrade as tg

from reference.pixels import pixels, rows
from reference.tonemap import AP0_2_AP1, SRGB_2_AP0

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

MID_GREY_CODE = 0.4135884  # ACEScc/ACEScct of 0.18


def _samples():
    rng = np.random.default_rng(5)
    rgb = 10.0 ** rng.uniform(-4, 1.5, (600, 3))  # 1e-4..30: the toe and the log segment
    return np.concatenate([rgb, [[0.18, 0.18, 0.18], [0.0, 0.0, 0.0], [1e-3, 2e-3, 5e-3]]])


def _expected(rgb, amount):
    """Unity's Rec.709 -> ACEScg, ACEScct contrast about mid grey (colour-science's ACEScct), back, clamped at 0 in ACES."""
    to_cg = AP0_2_AP1 @ SRGB_2_AP0
    log = colour.models.log_encoding_ACEScct(rgb @ to_cg.T)
    cg = colour.models.log_decoding_ACEScct((log - MID_GREY_CODE) * (1 + amount / 100) + MID_GREY_CODE)
    aces = np.maximum(np.maximum(cg, 0) @ np.linalg.inv(AP0_2_AP1).T, 0)
    return aces @ np.linalg.inv(SRGB_2_AP0).T


@pytest.mark.parametrize("amount", [-60.0, 25.0, 100.0])
def test_contrast_in_acescct_matches_colour_science(amount):
    rgb = _samples()
    ours = rows(tg.ColorGrade(aces=True, log_space="acescct", contrast=amount)(pixels(rgb)))
    np.testing.assert_allclose(ours, _expected(rgb, amount), rtol=2e-6, atol=1e-9)


def test_log_segment_is_a_power_law_about_grey_and_the_toe_is_linear():
    k = 1.5
    grade = tg.ColorGrade(aces=True, log_space="acescct", contrast=50.0)
    cg = torch.tensor([0.18, 0.05, 2.0, 0.0])[None, :, None, None].expand(1, 4, 3, 1).transpose(1, 2).double()  # ACEScg greys
    out = tg.color.unity_to_acescg(grade(tg.color.acescg_to_unity(cg)))[0, 1, :, 0]
    # Above 2^-7 ACEScct is log2: contrast k about grey is 0.18 (x / 0.18)^k.
    torch.testing.assert_close(out[:3], 0.18 * (cg[0, 1, :3, 0] / 0.18) ** k, rtol=1e-6, atol=0)
    # Black sits on the straight toe at code B: contrast moves it to (B - grey) k + grey, which is below 0.
    toe_code = (0.0729055341958355 - 0.4135884) * k + 0.4135884
    assert toe_code < 0.0729055341958355 and float(out[3]) == 0.0


def test_gradients_are_finite_through_the_toe_and_cut():
    image = torch.tensor([0.0, 1e-30, 0.0078125, 0.18, 65504.0, -1.0]).reshape(1, 1, 2, 3).expand(1, 3, 2, 3).clone().requires_grad_()
    amount = torch.tensor(40.0, requires_grad=True)
    tg.ColorGrade(aces=True, log_space="acescct", contrast=amount)(image).sum().backward()
    assert torch.isfinite(image.grad).all() and torch.isfinite(amount.grad)


def test_config_round_trip_and_rules():
    grade = tg.ColorGrade(aces=True, log_space="acescct", contrast=10)
    assert grade.to_config() == {"aces": True, "log_space": "acescct", "contrast": 10}
    assert tg.ColorGrade(**grade.to_config()).to_config() == grade.to_config()
    assert tg.ColorGrade(aces=True, log_space="acescct").is_identity
    with pytest.raises(ValueError, match="aces=True"):
        tg.ColorGrade(log_space="acescct", contrast=10)
    with pytest.raises(ValueError, match="log_space"):
        tg.ColorGrade(aces=True, log_space="logc")


def test_graph_input_export_form_keeps_acescct():
    from torchgrade.onnx.graph import GRADE_INPUTS, export_graph

    grade = tg.ColorGrade(aces=True, log_space="acescct", contrast=30.0)
    graph = export_graph(grade, grade_inputs=True)
    image = torch.rand(1, 3, 4, 4) * 4
    assert graph.stages[0].log_space == "acescct"
    controls = [torch.as_tensor(getattr(grade, name), dtype=torch.float32).unsqueeze(0) for name in GRADE_INPUTS]  # a batch of one
    # the graph computes every step of its tensor controls (exposure 0 too), the stage only those of its numbers: its
    # matrices in float32 where the stage's are folded in float64, float32 rounding through ACEScct's exponential
    torch.testing.assert_close(graph.stages[0](image, *controls), grade(image), rtol=5e-5, atol=1e-5)
