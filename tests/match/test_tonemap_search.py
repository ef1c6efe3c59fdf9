"""``match_look`` finds a look's tone mapper with every default, and says on held-out blocks what the rest of the
picture will show: a look fitted on the left half of a photograph, its truth measured on every pixel of the right."""

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.match import match_errors

LOOK = {"contrast": -10.0, "saturation": 30.0, "temperature": -20.0, "tint": 10.0}
"""A look of the global controls (the one a first screening mistook for ``aces_narkowicz``)."""

CLOSE = 0.01
"""Codes (p99.9) under which a held-out figure and the truth are both the fit's rounding: their ratio means nothing."""


@pytest.fixture(autouse=True)
def _one_thread():
    """Small fits: on a shared, loaded CPU a second thread mostly waits for the first."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def halves(exr_dir, name: str, step: int, rows: slice, columns: slice):
    """A crop of a photograph at every ``step``-th pixel, float64, and the column where its right half starts."""
    source = tg.io.read_exr(exr_dir / f"{name}.exr")[:3, ::step, ::step][:, rows, columns].double()
    return source, source.shape[-1] // 2


def truth(result, source, target, half: int) -> dict:
    """The fitted look against the known one on every pixel of the right half, which the fit never saw."""
    with torch.no_grad():
        matched = result.look(source[None, ..., half:])[0]
    return match_errors(target[..., half:].reshape(3, -1), matched.reshape(3, -1))


def assert_recipe(config: dict, tolerance: float = 1.0) -> None:
    """Every default control of the fitted grade is :data:`LOOK`'s, or the identity where the look leaves it:
    within ``0.05 · tolerance`` of a -100..100 slider, ``0.005 · tolerance`` stop of exposure, 0.001 of a colour."""
    grade = config["grade"]
    for name in tg.match.GRADE_CONTROLS:
        expected = np.atleast_1d(LOOK.get(name, tg.ColorGrade.controls[name].default))
        found = np.atleast_1d(grade.get(name, tg.ColorGrade.controls[name].default))  # the config leaves out identities
        bound = {"post_exposure": 0.005 * tolerance}.get(name, 0.05 * tolerance if len(expected) == 1 else 1e-3)
        np.testing.assert_allclose(found, expected, rtol=0, atol=bound, err_msg=f"{name}: {config}")


def agrees(held_out: float, real: float) -> bool:
    """Whether the held-out p99.9 is within 1.5x of the real one (both under :data:`CLOSE`: agreeing)."""
    return max(held_out, real) <= CLOSE or (held_out <= 1.5 * real and real <= 1.5 * held_out)


@pytest.mark.parametrize("mode, picture", [
    ("agx", "GoldenGate"), ("aces", "CandleGlass"), ("neutral", "GoldenGate"), ("khronos_pbr_neutral", "Desk"),
    ("hable", "GoldenGate"), ("aces2", "CandleGlass"), ("reinhard_luminance", "Desk"), ("agx_godot", "GoldenGate"),
])
def test_a_known_look_with_any_tone_mapper_is_found_with_every_default(exr_dir, mode, picture):
    source, half = halves(exr_dir, picture, 8, slice(20, 84), slice(16, 144))
    with torch.no_grad():
        target = tg.PostFX(grade=LOOK, tonemap=mode)(source[None])[0]
    result = tg.match_look(source[..., :half], target[..., :half], progress=False)
    real, held_out = truth(result, source, target, half), result.errors["controls"]
    assert real["p99.9"] <= 0.5 and held_out["p99.9"] <= 0.5, (result.look.to_config(), real, held_out)
    assert agrees(held_out["p99.9"], real["p99.9"]), (held_out, real)
    assert_recipe(result.look.to_config())  # the recipe, not only the picture: no contrast traded for exposure and gamma


@pytest.mark.parametrize("mode, fitted", [("agx", "neutral"), ("hable", "aces"), ("aces", "reinhard")])
def test_the_held_out_figure_is_what_the_rest_of_the_picture_shows(exr_dir, mode, fitted):
    """A look no fitted tone mapper can reach: its held-out p99.9 is within 1.5x of the right half's, every pixel.
    Both halves of the photograph: a small crop's right half holds too few pixels for its 99.9th percentile to be
    more than its brightest few, which the left half may not have."""
    source, half = halves(exr_dir, "GoldenGate", 4, slice(None), slice(None))
    with torch.no_grad():
        target = tg.PostFX(grade=LOOK, tonemap=mode)(source[None])[0]
    result = tg.match_look(source[..., :half], target[..., :half], tonemaps=fitted, steps=40, progress=False)
    real, held_out = truth(result, source, target, half), result.errors["controls"]
    assert real["p99.9"] > 10 * CLOSE, real  # a figure worth predicting
    assert agrees(held_out["p99.9"], real["p99.9"]), (held_out, real)


def test_an_8_bit_target_keeps_the_recipe_of_the_global_controls(exr_dir):
    """Saved as 8-bit codes, the target is the look to within half a code: lift, gamma and gain would fit only the
    rounding, and are left at the identity; the global controls are found within their rounding."""
    source, half = halves(exr_dir, "GoldenGate", 8, slice(20, 84), slice(16, 144))
    with torch.no_grad():
        shown = tg.PostFX(grade=LOOK, tonemap="agx")(source[None])[0]
    target = tg.color.srgb_to_linear(torch.round(255.0 * tg.color.linear_to_srgb(shown)) / 255.0)
    result = tg.match_look(source[..., :half], target[..., :half], progress=False)
    config = result.look.to_config()
    assert config["tonemap"] == {"mode": "agx"} and list(dict(result.phases)) == ["global controls", "every control"]
    assert not {"lift", "gamma", "gain", "split_shadows", "split_highlights"} & set(config["grade"]), config
    assert_recipe(config, tolerance=10.0)
    assert truth(result, source, shown, half)["p99.9"] <= 0.5
