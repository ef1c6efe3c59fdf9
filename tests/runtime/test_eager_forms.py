"""Eager forms used when nothing records gradients (``torchgrade.runtime.recording.untracked``): the same values as the
guarded forms autograd runs, on HDR inputs with zeros, negatives, 65504, Inf and NaN."""

import math

import pytest
import torch

import torchgrade as tg
from torchgrade.color import aces_to_acescc, acescc_to_aces, safe_pow
from torchgrade.base.planes import apply_matrix
from torchgrade.runtime.recording import untracked

HDR = "../shared/data/exr/Desk.exr"
EDGES = (0.0, -0.0, 1e-30, 2.0**-16, 2.0**-15, 0.18, 1.0, 60.0, 65504.0, -1.0, -65504.0, math.inf, -math.inf, math.nan)


def hdr_frame(height=48, width=64) -> torch.Tensor:
    """Scene-referred values over 30 stops, channels within 4 stops of each other, a fifth of the values negative
    (out of gamut), and every edge value in each channel.

    Channels apart by more cancel in the colour matrices to a few float32 steps of the other ones, and any order of
    summation (einsum's, the eager form's, float64's) then gives another value.
    """
    torch.manual_seed(0)
    frame = torch.exp2(torch.rand(1, 1, height, width) * 30.0 - 20.0) * torch.exp2(torch.rand(1, 3, height, width) * 4.0 - 2.0)
    frame = torch.where(torch.rand_like(frame) < 0.2, -0.05 * frame, frame)
    edges = torch.tensor(EDGES)
    frame[0, :, 0, : len(EDGES)] = torch.stack((edges, edges.roll(1), edges.roll(2)))
    return frame


def recorded(function, image: torch.Tensor) -> torch.Tensor:
    """``function(image)`` with autograd recording, so every guarded form runs."""
    return function(image.clone().requires_grad_()).detach()


def unrecorded(function, image: torch.Tensor) -> torch.Tensor:
    with torch.no_grad():
        assert untracked(image)
        return function(image)


STAGES = {
    "cinematic grade": lambda: tg.ColorGrade(aces=True, post_exposure=0.3, temperature=8, contrast=15, saturation=10,
                                             split_shadows=(0.45, 0.5, 0.56), split_highlights=(0.56, 0.5, 0.45)),
    "linear grade, saturation and split toning": lambda: tg.ColorGrade(contrast=-30, saturation=-40, split_balance=20,
                                                                       split_shadows=(0.2, 0.9, 0.5), split_highlights=(0.5, 0.1, 0.7)),
    "saturation with a curve": lambda: tg.ColorGrade(aces=True, saturation=25, sat_vs_sat=((0.0, 0.3), (1.0, 0.6))),
    "aces": lambda: tg.ToneMap("aces"),
    "aces, unclipped": lambda: tg.ToneMap("aces", clip=False),
    "aces_reference": lambda: tg.ToneMap("aces_reference"),
    "unreal_filmic": lambda: tg.ToneMap("unreal_filmic"),
    "reinhard": lambda: tg.ToneMap("reinhard"),
    "aces2": lambda: tg.ToneMap("aces2"),
}


@pytest.fixture(scope="module")
def frames():
    desk = tg.io.read_exr(HDR)[:3].unsqueeze(0)[..., :96, :128]
    return {"desk": desk, "synthetic": hdr_frame()}


def colour_error(actual: torch.Tensor, reference: torch.Tensor) -> float:
    """The largest distance of ``actual`` to the float64 ``reference``, each channel in units of its pixel's largest
    channel: the scale at which float32 colour matrices round. NaN must sit where the reference has it."""
    assert torch.equal(actual.isnan(), reference.isnan())
    scale = reference.abs().amax(dim=-3, keepdim=True).clamp_min(1e-6)
    return ((actual.double() - reference) / scale).abs().nan_to_num(0.0).max().item()


@pytest.mark.parametrize("name", STAGES)
def test_stages_are_as_close_to_float64_as_the_recorded_forms(name, frames):
    layer = STAGES[name]()
    for image in frames.values():
        reference = recorded(layer, image.double())
        fast, guarded = unrecorded(layer, image), recorded(layer, image)
        # Out-of-gamut colours cancel in the matrices (7e-4 of the pixel on the synthetic frame for both forms), so the
        # two float32 forms differ by as much; a form that took another branch would be far from float64.
        assert colour_error(fast, reference) <= 1.1 * colour_error(guarded, reference) + 1e-6


@pytest.mark.parametrize("exponent", [0.5, 1.0 / 2.2, 2.2, 3])
def test_safe_pow_is_the_guarded_power(exponent):
    x = torch.cat((torch.tensor(EDGES), torch.randn(1000) * 100.0))
    torch.testing.assert_close(unrecorded(lambda t: safe_pow(t, exponent), x), recorded(lambda t: safe_pow(t, exponent), x),
                               rtol=0.0, atol=0.0, equal_nan=True)


def test_acescc_segments_without_selects():
    x = torch.cat((torch.tensor(EDGES), torch.logspace(-30, 5, 20001), -torch.logspace(-30, 5, 101)))
    torch.testing.assert_close(unrecorded(aces_to_acescc, x), recorded(aces_to_acescc, x), rtol=0.0, atol=0.0, equal_nan=True)
    codes = torch.cat((torch.tensor(EDGES), torch.linspace(-1.0, 2.0, 30001)))
    # the low segment's (v - 2^-16)·2 meets v at the knee: float rounding may pick the other one there
    torch.testing.assert_close(unrecorded(acescc_to_aces, codes), recorded(acescc_to_aces, codes), rtol=1e-6, atol=1e-12, equal_nan=True)


@pytest.mark.parametrize("shape", [(3, 3), (2, 3, 3)])
def test_matrix_by_channels_against_float64(shape):
    torch.manual_seed(1)
    matrix, image = torch.randn(shape), torch.rand(2, 3, 5, 7) * 100.0
    expected = torch.einsum("...ij,...jhw->...ihw", matrix.double(), image.double()).float()
    assert untracked(matrix, image)
    torch.testing.assert_close(apply_matrix(matrix, image), expected, rtol=1e-5, atol=1e-4)


def _grade_jacobians(controls: dict, image: torch.Tensor):
    """The Jacobian of a grade's output with respect to each of ``controls``, by forward mode (``torch.func.jacfwd``)
    and by reverse mode (autograd: ``torch.autograd.functional.jacobian``)."""
    names = list(controls)

    def graded(*values):
        return tg.ColorGrade(**dict(zip(names, values)))(image)

    values = tuple(torch.as_tensor(controls[name], dtype=torch.float64) for name in names)
    forward = torch.func.jacfwd(graded, argnums=tuple(range(len(names))))(*values)
    reverse = torch.autograd.functional.jacobian(graded, values)
    return dict(zip(names, forward)), dict(zip(names, reverse))


@pytest.mark.parametrize("controls", [
    {"contrast": 0.0, "saturation": 0.0, "hue_shift": 0.0},  # identities: the steps skipped for plain values
    {"split_shadows": (0.4, 0.5, 0.6), "split_highlights": (0.6, 0.5, 0.4), "split_balance": 20.0},
])
def test_forward_mode_derivatives_equal_autograd(controls):
    # jacfwd wraps tensors without requires_grad: a step skipped at its identity gave a zero column, and the
    # in-place eager power of split toning a NaN one
    image = torch.rand(1, 3, 4, 5, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 0.5
    image[0, :, 0, :3] = torch.tensor([0.0, -0.5, 60.0])  # black, out of gamut and bright
    forward, reverse = _grade_jacobians(controls, image)
    for name in controls:
        assert torch.isfinite(forward[name]).all() and forward[name].abs().max() > 0, name
        torch.testing.assert_close(forward[name], reverse[name], rtol=1e-9, atol=1e-12, msg=name)
