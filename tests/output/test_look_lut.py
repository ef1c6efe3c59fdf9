"""The creative look LUT after tone mapping (``LookLUT``, the look's ``look_lut`` slot), against OpenColorIO applying
the same ``.cube`` and CLF files to the same tone-mapped pixels, blended as Unity URP's Color Lookup blends."""

import json
import warnings

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.color import linear_to_srgb, srgb_to_linear
from torchgrade.output.layer import LookLUT
from torchgrade.lut import LUTAccuracyWarning

OCIO = pytest.importorskip("PyOpenColorIO")
SIZE = 17
OCIO_INTERPOLATION = {"tetrahedral": OCIO.INTERP_TETRAHEDRAL, "trilinear": OCIO.INTERP_LINEAR}


def creative(r, g, b):
    """A show look in sRGB codes, written from its formula: an S-curve, warmer highlights, a little cross-talk."""
    s = lambda c: c * c * (3.0 - 2.0 * c)  # noqa: E731
    return (np.clip(s(r) + 0.06 * (g - b), 0, 1), np.clip(0.95 * s(g) + 0.03 * (r - b), 0, 1), np.clip(0.85 * s(b) + 0.04 * g, 0, 1))


def lattice_rows(blue_fastest: bool) -> np.ndarray:
    """The creative look on the SIZE³ lattice, one row a point: red fastest (.cube) or blue fastest (CLF)."""
    steps = np.linspace(0.0, 1.0, SIZE)
    slow, mid, fast = np.meshgrid(steps, steps, steps, indexing="ij")
    r, g, b = (slow, mid, fast) if blue_fastest else (fast, mid, slow)
    return np.stack(creative(r, g, b), axis=-1).reshape(-1, 3)


@pytest.fixture(scope="module")
def cube_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("looks") / "show.cube"
    rows = "\n".join(" ".join(f"{v:.8f}" for v in row) for row in lattice_rows(blue_fastest=False))
    path.write_text(f'TITLE "show"\nLUT_3D_SIZE {SIZE}\n{rows}\n')
    return path


@pytest.fixture(scope="module")
def clf_file(tmp_path_factory):
    """The same look as CLF, as another application writes it: a namespace, 10-bit integer output codes."""
    path = tmp_path_factory.mktemp("looks") / "show.clf"
    codes = np.round(lattice_rows(blue_fastest=True) * 1023.0)
    rows = "\n".join(" ".join(f"{int(v)}" for v in row) for row in codes)
    path.write_text(f'<?xml version="1.0" encoding="UTF-8"?>\n<ProcessList xmlns="urn:AMPAS:CLF:v3.0" id="show" compCLFversion="3.0">\n'
                    f'<LUT3D inBitDepth="32f" outBitDepth="10i" interpolation="tetrahedral">\n<Array dim="{SIZE} {SIZE} {SIZE} 3">\n'
                    f"{rows}\n</Array>\n</LUT3D>\n</ProcessList>\n")
    return path


@pytest.fixture(scope="module")
def tone_mapped(exr_dir):
    """Real frames, tone mapped: what a look LUT receives (two sample images, shrunk 8x)."""
    frames = [torch.nn.functional.avg_pool2d(tg.io.read_exr(exr_dir / name)[:3].unsqueeze(0), 8) for name in ("Desk.exr", "GoldenGate.exr")]
    with torch.no_grad():
        return [tg.ToneMap("aces")(frame) for frame in frames]


def ocio_look(path, display_linear: torch.Tensor, contribution: float, interpolation: str = "tetrahedral") -> torch.Tensor:
    """Unity URP's Color Lookup with OpenColorIO as the LUT: sRGB codes of the clamped light, the file applied by
    OpenColorIO, blended by ``contribution`` in codes, decoded; float64 around OpenColorIO's float32."""
    codes = linear_to_srgb(display_linear.double().clamp(0, 1))[0].permute(1, 2, 0).numpy()
    looked = np.ascontiguousarray(codes.astype(np.float32))
    transform = OCIO.FileTransform(src=str(path), interpolation=OCIO_INTERPOLATION[interpolation])
    OCIO.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor().applyRGB(looked)
    blended = np.clip(codes + contribution * (looked.astype(np.float64) - codes), 0, 1)
    return srgb_to_linear(torch.from_numpy(blended).permute(2, 0, 1).unsqueeze(0))


def codes_apart(a: torch.Tensor, b: torch.Tensor) -> float:
    """The largest difference in 8-bit sRGB codes."""
    return float((linear_to_srgb(a.double()) - linear_to_srgb(b.double())).abs().max() * 255)


@pytest.mark.parametrize("contribution", [1.0, 0.35])
@pytest.mark.parametrize("interpolation", ["tetrahedral", "trilinear"])
def test_a_cube_look_lut_matches_opencolorio_on_tone_mapped_frames(cube_file, tone_mapped, contribution, interpolation):
    look = LookLUT(cube_file, contribution=contribution, interpolation=interpolation)
    for frame in tone_mapped:
        with torch.no_grad():
            assert codes_apart(look(frame), ocio_look(cube_file, frame, contribution, interpolation)) < 0.01


def test_a_clf_look_lut_matches_opencolorio(clf_file, tone_mapped):
    look = LookLUT(clf_file, contribution=0.8)
    assert look.lut.interpolation == "tetrahedral" and look.lut.size == SIZE
    for frame in tone_mapped:
        with torch.no_grad():
            assert codes_apart(look(frame), ocio_look(clf_file, frame, 0.8)) < 0.01


def test_the_look_lut_runs_after_tone_mapping_in_a_look(cube_file, tone_mapped, exr_dir):
    scene = torch.nn.functional.avg_pool2d(tg.io.read_exr(exr_dir / "Desk.exr")[:3].unsqueeze(0), 8)
    look = tg.PostFX(grade={"contrast": 10}, tonemap="aces", look_lut={"lut": str(cube_file), "contribution": 0.5}, display="sdr")
    assert list(look.stages()) == ["grade", "tonemap", "look_lut", "display"]
    with torch.no_grad():
        graded = tg.ToneMap("aces")(tg.ColorGrade(contrast=10)(scene))
        expected = linear_to_srgb(ocio_look(cube_file, graded, 0.5))
        assert float((look(scene).double() - expected).abs().max() * 255) < 0.01


def test_a_look_lut_needs_display_referred_light_before_it(cube_file):
    with pytest.raises(ValueError, match="look_lut takes display-referred light"):
        tg.PostFX(grade={"contrast": 10}, look_lut=str(cube_file))
    with pytest.raises(ValueError, match="look_lut takes display-referred values"):
        tg.RandomPostFX(contrast=10, look_lut=str(cube_file))


def test_contribution_zero_is_no_stage_and_one_is_the_whole_lut(cube_file, tone_mapped):
    assert "look_lut" not in tg.PostFX(tonemap="aces", look_lut={"lut": str(cube_file), "contribution": 0.0}).stages()
    frame = tone_mapped[0]
    with torch.no_grad():
        whole = LookLUT(cube_file)(frame)
        codes = linear_to_srgb(frame.clamp(0, 1))
        assert codes_apart(whole, srgb_to_linear(LookLUT(cube_file).lut(codes))) < 1e-3


def test_a_config_names_the_file_beside_it_and_round_trips(tmp_path, cube_file):
    (tmp_path / "show.cube").write_bytes(cube_file.read_bytes())
    config = {"tonemap": "neutral", "look_lut": {"lut": "show.cube", "contribution": 0.25}}
    (tmp_path / "look.json").write_text(json.dumps(config))
    look = tg.PostFX.from_config(tmp_path / "look.json")
    assert look.look_lut.contribution == 0.25 and look.look_lut.source == str(tmp_path / "show.cube")
    again = tg.PostFX.from_config(json.loads(json.dumps(look.to_config())))
    image = torch.rand(1, 3, 8, 8) * 4
    with torch.no_grad():
        assert torch.equal(again(image), look(image))


def test_a_look_lut_given_as_a_table_round_trips_through_json_and_a_state_dict(tmp_path):
    table = torch.from_numpy(lattice_rows(blue_fastest=False).reshape(SIZE, SIZE, SIZE, 3)).float()
    look = tg.PostFX(tonemap="aces", look_lut=LookLUT(table, contribution=0.6, interpolation="trilinear"))
    image = torch.rand(2, 3, 8, 8) * 8
    with torch.no_grad():
        expected = look(image)
        assert torch.equal(tg.PostFX.from_config(json.loads(json.dumps(look.to_config())))(image), expected)
        torch.save(look.state_dict(), tmp_path / "look.pt")
        loaded = tg.PostFX()
        loaded.load_state_dict(torch.load(tmp_path / "look.pt", weights_only=True))
        assert loaded.look_lut.lut.interpolation == "trilinear"
        assert torch.equal(loaded(image), expected)


def test_baking_keeps_the_look_lut_live_after_the_baked_lut(cube_file):
    look = tg.PostFX(grade={"contrast": 10}, tonemap="aces", look_lut=str(cube_file))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        baked = look.to_lut(17)
    assert list(baked.stages()) == ["lut", "look_lut"]
    assert baked.look_lut is not look.look_lut and torch.equal(baked.look_lut.lut.table, look.look_lut.lut.table)


def test_per_sample_and_learnable_contributions_have_finite_gradients(cube_file):
    image = (torch.rand(3, 3, 6, 6) * 1.2).requires_grad_()
    contribution = torch.nn.Parameter(torch.tensor([0.0, 0.5, 1.0]))
    look = LookLUT(cube_file, contribution=contribution)
    out = look(image)
    out.sum().backward()
    assert torch.isfinite(image.grad).all() and torch.isfinite(contribution.grad).all()
    with torch.no_grad():
        assert torch.allclose(out[0], image[0].clamp(0, 1), atol=1e-6)  # contribution 0: the clamped input


@pytest.mark.parametrize("value", [0.0, 1e-45, 0.18, 1.0, 60.0, 65504.0, 1e30, float("nan"), float("inf"), -float("inf"), -0.5])
def test_extreme_inputs_give_display_values(cube_file, value):
    out = LookLUT(cube_file)(torch.full((1, 3, 2, 2), value))
    assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= 1


def test_random_post_fx_draws_the_contribution_and_never_mixes_value_ranges(cube_file):
    augment = tg.RandomPostFX(contrast=20, tonemap="aces", look_lut=str(cube_file), look_lut_contribution=(0.2, 0.9), p=0.5)
    images = torch.rand(16, 3, 8, 8) * 30
    out = augment(images, generator=torch.Generator().manual_seed(1))
    params = augment.last_params
    assert out.max() <= 1.0  # every sample tone mapped, skipped ones too
    skipped = ~params["batch_prob"]
    assert skipped.any() and params["batch_prob"].any()
    contributions = params["look_lut_contribution"]
    assert contributions.min() >= 0.2 and contributions.max() <= 0.9
    with torch.no_grad():
        tone_mapped = tg.ToneMap("aces")(images[skipped])
        assert torch.allclose(out[skipped], tone_mapped, atol=1e-6)  # skipped: no grade, no look, but tone mapped
        i = int(torch.nonzero(params["batch_prob"])[0])
        graded = tg.ToneMap("aces")(tg.ColorGrade(contrast=params["contrast"][i])(images[i : i + 1]))
        expected = LookLUT(cube_file, contribution=float(contributions[i]))(graded)
        assert torch.allclose(out[i : i + 1], expected, atol=1e-5)
    assert torch.equal(augment(images, params=params), out)
    assert tg.RandomPostFX.from_config(augment.to_config()).to_config() == augment.to_config()


def test_the_exported_look_lut_runs_on_onnxruntime(tmp_path, cube_file, tone_mapped):
    ort = pytest.importorskip("onnxruntime")
    look = tg.PostFX(tonemap="aces", look_lut={"lut": str(cube_file), "contribution": 0.7})
    path = tg.onnx.export(look, tmp_path / "look.onnx")
    image = torch.rand(2, 3, 21, 34) * 20
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    served = torch.from_numpy(session.run(None, {"image": image.numpy()})[0])
    with torch.no_grad():
        assert codes_apart(served, look(image)) < 0.05


def test_grade_applies_a_look_lut_from_the_command_line(tmp_path, cube_file, exr_dir):
    from torchgrade.cli import main

    frame = torch.nn.functional.avg_pool2d(tg.io.read_exr(exr_dir / "Desk.exr")[:3].unsqueeze(0), 8)[0]
    tg.io.write_exr(tmp_path / "frame.exr", frame, half=False)
    assert main(["grade", str(tmp_path / "frame.exr"), "-o", str(tmp_path / "out.exr"), "--tonemap", "aces", "--contrast", "10",
                 "--look-lut", str(cube_file), "--look-lut-contribution", "0.5", "--quiet"]) == 0
    graded = tg.io.read_exr(tmp_path / "out.exr")[:3].unsqueeze(0)
    with torch.no_grad():
        expected = tg.PostFX(grade={"contrast": 10, "aces": True}, tonemap="aces", look_lut={"lut": str(cube_file), "contribution": 0.5})(frame.unsqueeze(0))
    assert codes_apart(graded, expected) < 0.5  # written as half floats
    assert main(["grade", str(tmp_path / "frame.exr"), "-o", str(tmp_path / "out2.exr"), "--look-lut-contribution", "0.5", "--quiet"]) == 2
    assert not (tmp_path / "out2.exr").exists()


def test_an_interpolation_given_with_a_lut_leaves_the_callers_lut_as_it_was():
    table = torch.from_numpy(lattice_rows(blue_fastest=False).reshape(SIZE, SIZE, SIZE, 3)).float()
    lut = tg.LUT3D(table)
    look = LookLUT(lut, interpolation="trilinear")
    baked = tg.PostFX(lut=lut, interpolation="trilinear")
    assert lut.interpolation == "tetrahedral"
    assert look.lut.interpolation == baked.lut.interpolation == "trilinear" and look.lut.table is lut.table
    with pytest.raises(ValueError, match="interpolation must be one of"):
        LookLUT(lut, interpolation="cubic")
