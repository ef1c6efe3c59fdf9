"""Saving looks with torch: whole modules and state dicts read back under ``weights_only=True``."""

import copy
import subprocess
import sys

import pytest
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


# --- a saved look is untrusted: what loads is checked as construction checks it ----------------------


def test_a_pickled_look_with_a_control_out_of_range_is_refused_at_load(tmp_path):
    look = tg.PostFX(tonemap={"mode": "reinhard_extended", "white_point": 4.0})
    look.tonemap.__dict__["white_point"] = 0.0  # what editing the file gives: the pickle holds the value as it is
    torch.save(look, tmp_path / "look.pt")
    with pytest.raises(ValueError, match=r"white_point must lie in \[0.001, 10000.0\], got 0.0"):
        torch.load(tmp_path / "look.pt", weights_only=True)


def test_a_state_dict_with_a_nan_lut_entry_is_refused_at_load():
    baked = tg.PostFX(grade={"contrast": 20}, tonemap="aces").to_lut(5)
    state = baked.state_dict()
    state["lut.table"] = state["lut.table"].clone()
    state["lut.table"][1, 2, 3, 0] = float("nan")
    with pytest.raises(ValueError, match="LUT table must be finite"):
        tg.PostFX(lut=tg.LUT3D(tg.lut.identity_table(5))).load_state_dict(state)


def test_a_state_dict_with_a_control_tensor_out_of_range_is_refused_at_load():
    grade = tg.ColorGrade(contrast=torch.tensor([10.0, 20.0]))
    state = grade.state_dict()
    state["contrast"] = torch.tensor([10.0, 500.0])
    with pytest.raises(ValueError, match="contrast must lie in"):
        tg.ColorGrade(contrast=torch.tensor([0.0, 0.0])).load_state_dict(state)


@pytest.mark.parametrize("extra", [
    "a string", {"parameters": [], "interpolation": "tetrahedral"}, {"stages": {"grade": 3}, "parameters": [], "interpolation": "tetrahedral"},
    {"stages": {"sharpen": {}}, "parameters": [], "interpolation": "tetrahedral"}, {"stages": {}, "parameters": "all", "interpolation": "tetrahedral"},
    {"stages": {}, "parameters": [], "interpolation": "cubic"},
])
def test_a_malformed_extra_state_is_a_value_error_saying_what(extra):
    state = tg.PostFX(grade={"contrast": 20}).state_dict()
    state["_extra_state"] = extra
    with pytest.raises(ValueError, match="_extra_state is malformed"):
        tg.PostFX().load_state_dict(state)


def test_a_config_number_too_large_for_a_float_in_a_saved_look_is_a_value_error():
    state = tg.PostFX(grade={"contrast": 20}).state_dict()
    state["_extra_state"]["stages"]["grade"]["contrast"] = int("9" * 400)
    with pytest.raises(ValueError, match="grade.contrast must be a number a float can hold"):
        tg.PostFX().load_state_dict(state)


def test_a_pickled_random_layer_with_a_range_out_of_bounds_is_refused_at_load(tmp_path):
    layer = tg.RandomPostFX(contrast=20)
    layer.grade_ranges["contrast"] = (-20.0, 500.0)
    torch.save(layer, tmp_path / "augment.pt")
    with pytest.raises(ValueError, match="contrast"):
        torch.load(tmp_path / "augment.pt", weights_only=True)


@pytest.mark.parametrize("assign", [False, True], ids=["copied", "assigned"])
def test_a_state_dict_refused_at_load_leaves_the_stage_as_it_was(assign):
    grade = tg.ColorGrade(contrast=torch.tensor([10.0, 20.0]), saturation=torch.tensor(5.0))
    state = {**grade.state_dict(), "contrast": torch.tensor([10.0, 500.0]), "saturation": torch.tensor(7.0)}
    with pytest.raises((ValueError, RuntimeError), match="contrast must lie in"):  # assigned: load_state_dict's report
        grade.load_state_dict(state, assign=assign)
    assert grade.contrast.tolist() == [10.0, 20.0] and grade.saturation.item() == 5.0
    lut = tg.LUT3D(tg.lut.identity_table(5))
    state = {**lut.state_dict(), "table": torch.full((5, 5, 5, 3), float("nan"))}
    with pytest.raises(ValueError, match="LUT table must be finite"):
        lut.load_state_dict(state, assign=assign)
    assert torch.equal(lut.table, tg.lut.identity_table(5))


def test_a_stage_on_meta_deep_copies():
    for stage in (tg.ColorGrade(contrast=torch.nn.Parameter(torch.tensor(10.0)), shadows_start=torch.tensor([0.0, 0.1])),
                  tg.LUT3D(tg.lut.identity_table(5)), tg.ConvolutionBloom(torch.ones(1, 3, 3)),
                  tg.PrimaryGrade(style="log", pivot_black=torch.tensor(0.0))):
        copied = copy.deepcopy(stage.to("meta"))
        assert all(tensor.is_meta for tensor in copied.state_dict().values())


def test_a_stage_an_optimiser_moved_out_of_range_copies_and_raises_at_its_next_forward():
    grade = tg.ColorGrade(contrast=torch.nn.Parameter(torch.tensor(10.0)))
    with torch.no_grad():
        grade.contrast.fill_(500.0)  # what an optimiser step could do
    averaged = torch.optim.swa_utils.AveragedModel(grade)  # deep-copies the stage
    assert averaged.module.contrast.item() == 500.0
    with pytest.raises(ValueError, match=r"contrast must lie in \[-100.0, 100.0\], got 500.0"):
        averaged(torch.rand(1, 3, 2, 2))


def test_a_random_layer_saved_whole_loads_in_a_fresh_process_under_weights_only(tmp_path):
    """``import torchgrade`` alone (no kornia: it is imported when a file holds a layer) reads a saved layer back."""
    path = tmp_path / "augment.pt"
    torch.save(tg.RandomPostFX(contrast=20, tonemap=("aces", "neutral")), path)
    load = ("import sys, torch, torchgrade; assert 'kornia' not in sys.modules; "
            f"layer = torch.load({str(path)!r}, weights_only=True); print(type(layer).__name__, layer.ranges, layer.tonemap)")
    result = subprocess.run([sys.executable, "-c", load], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["RandomPostFX", "{'contrast':", "(-20.0,", "20.0)}", "('aces',", "'neutral')"]
