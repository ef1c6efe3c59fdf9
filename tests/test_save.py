"""Saving looks with torch: whole modules and state dicts read back under ``weights_only=True``."""

import torch

import torchgrade as tg


def full_look():
    grade = {"contrast": torch.nn.Parameter(torch.tensor(20.0)), "split_shadows": (0.4, 0.5, 0.6), "saturation": 10}
    return tg.PostFX(exposure={"metering": "mean"}, bloom={"intensity": 0.5}, grade=grade, primary={"saturation": 1.1},
                     tonemap="aces", dither={"amplitude": 1 / 255})


def frames():
    generator = torch.Generator().manual_seed(0)
    return [torch.rand(1, 3, 16, 16, generator=generator) * scale for scale in (1.0, 4.0, 2.0)]


def test_whole_look_round_trips_under_weights_only(tmp_path):
    look = full_look()
    first, second, third = frames()
    look(first, dt=0.1), look(second, dt=0.1)  # mid-shot: the eye adaptation is part of the state
    torch.save(look, tmp_path / "look.pt")
    loaded = torch.load(tmp_path / "look.pt", weights_only=True)
    assert loaded.to_config() == look.to_config()
    assert torch.equal(loaded(third, dt=0.1), look(third, dt=0.1))


def test_state_dict_rebuilds_the_look_in_an_empty_postfx(tmp_path):
    look = full_look()
    first, second, third = frames()
    look(first, dt=0.1), look(second, dt=0.1)
    torch.save(look.state_dict(), tmp_path / "look.pt")
    loaded = tg.PostFX()
    loaded.load_state_dict(torch.load(tmp_path / "look.pt", weights_only=True))
    assert loaded.to_config() == look.to_config() and list(loaded.stages()) == list(look.stages())
    assert isinstance(loaded.grade.contrast, torch.nn.Parameter), "a learnable control should stay learnable"
    assert torch.equal(loaded.exposure.adapted_luminance, look.exposure.adapted_luminance)
    assert torch.equal(loaded(third, dt=0.1), look(third, dt=0.1))


def test_baked_look_and_random_layer_round_trip(tmp_path):
    baked = tg.PostFX(grade={"contrast": 20}, tonemap="neutral").to_lut(5)
    torch.save(baked, tmp_path / "baked.pt")
    image = frames()[1]
    assert torch.equal(torch.load(tmp_path / "baked.pt", weights_only=True)(image), baked(image))
    augment = tg.RandomPostFX(contrast=20, tonemap=("aces", "neutral"))
    torch.save(augment, tmp_path / "augment.pt")
    loaded = torch.load(tmp_path / "augment.pt", weights_only=True)
    seed = torch.Generator().manual_seed
    assert torch.equal(loaded(image, generator=seed(1)), augment(image, generator=seed(1)))
