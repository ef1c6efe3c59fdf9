"""match_look: targets made by known looks (controls recovered) and by OpenColorIO (matched with a residual LUT)."""

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.lut import ErrorReport, LUTAccuracyWarning
from torchgrade.match import ResidualLUT, delta_e_2000, linear_to_lab, match_errors
from torchgrade.match.bounded import BoundedControls, fittable_names
from torchgrade.match.pixels import sample_pairs
from torchgrade.match.residual import monotonicity

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

pytest.importorskip("PyOpenColorIO")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.common import ocio_apply, ocio_look, ocio_processor  # noqa: E402  (the look bench_match.py learns)


@pytest.fixture(autouse=True)
def _one_thread():
    """The fits here are a few thousand pixels, too few to share among threads: on a shared, loaded CPU a second
    thread mostly waits for the first."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def scene(exr_dir, name="GoldenGate.exr", step=16):
    """A real HDR picture, subsampled to a few thousand pixels, float64."""
    return tg.io.read_exr(exr_dir / name)[:3, ::step, ::step].double()


def test_delta_e_2000_and_lab_match_colour_science():
    rng = np.random.default_rng(1)
    rgb = rng.uniform(0.0, 1.0, (500, 3)) ** 2
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    theirs = colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, "ITU-R BT.709", apply_cctf_decoding=False), white)
    np.testing.assert_allclose(linear_to_lab(torch.from_numpy(rgb.T)).numpy().T, theirs, atol=1e-6)
    lab1 = np.stack([rng.uniform(0, 100, 2000), rng.uniform(-100, 100, 2000), rng.uniform(-100, 100, 2000)], axis=1)
    lab2 = lab1 + rng.normal(0.0, 4.0, lab1.shape)
    lab1[:20, 1:], lab2[10:30, 1:] = 0.0, 0.0  # neutral colours, where the hue is undefined
    ours = delta_e_2000(torch.from_numpy(lab1.T), torch.from_numpy(lab2.T)).numpy()
    np.testing.assert_allclose(ours, colour.delta_E(lab1, lab2, method="CIE 2000"), atol=1e-9)


def test_match_errors_are_codes_and_mean_delta_e_as_colour_science_computes_them():
    rng = np.random.default_rng(2)
    reference = rng.uniform(-0.05, 1.05, (3, 4000))  # display-linear, a little outside the display on both sides
    fitted = reference + rng.normal(0.0, 0.01, reference.shape)
    shown = [np.clip(x, 0.0, 1.0).T for x in (reference, fitted)]
    codes = np.abs(255.0 * (colour.cctf_encoding(shown[0], "sRGB") - colour.cctf_encoding(shown[1], "sRGB"))).ravel()
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    lab = [colour.XYZ_to_Lab(colour.RGB_to_XYZ(x, "ITU-R BT.709", apply_cctf_decoding=False), white) for x in shown]
    errors = match_errors(torch.from_numpy(reference), torch.from_numpy(fitted))
    assert errors["max"] == pytest.approx(codes.max(), abs=1e-9)
    assert errors["p99.9"] == pytest.approx(np.quantile(codes, 0.999, method="inverted_cdf"), abs=1e-9)
    assert errors["delta_e_2000"] == pytest.approx(colour.delta_E(lab[0], lab[1], method="CIE 2000").mean(), abs=1e-6)


def test_held_out_pixels_are_whole_blocks_never_fitted():
    """Every pixel carries its own coordinates: the held-out ones are every pixel (inside the mask) of a quarter of the
    blocks, squares of side ceil(sqrt(40 * 50 / 64)) = 6, and no fitted pixel lies in one of those blocks."""
    rows, columns = torch.meshgrid(torch.arange(40.0), torch.arange(50.0), indexing="ij")
    source = torch.stack((rows, columns, torch.ones_like(rows))).double()
    mask = torch.rand(40, 50, generator=torch.Generator().manual_seed(3)) < 0.7
    pairs = sample_pairs(source, source * 2.0, mask, max_pixels=100000, holdout=0.25)
    train, test = ({(int(y), int(x)) for y, x, _ in p.reshape(3, -1).T.tolist()} for p in (pairs.train_source, pairs.test_source))
    inside = {(y, x) for y, x in zip(*torch.nonzero(mask, as_tuple=True)) for y, x in [(int(y), int(x))]}
    assert not train & test and train | test == inside
    blocks = {(y // 6, x // 6) for y, x in test}
    assert len(blocks) == round(0.25 * 7 * 9) and not blocks & {(y // 6, x // 6) for y, x in train}
    assert test == {(y, x) for y, x in inside if (y // 6, x // 6) in blocks}
    assert torch.equal(pairs.test_target, 2.0 * pairs.test_source) and torch.equal(pairs.train_target, 2.0 * pairs.train_source)


def test_fitting_pixels_are_drawn_evenly_over_colour_strata(exr_dir):
    """A stratum gives all its pixels or as many as any other gives, give or take one; highlights and saturated
    colours, few in a photograph, are fitted as well as its many mid-tones."""
    source = scene(exr_dir, step=4)
    pairs = sample_pairs(source, source, None, max_pixels=4096, holdout=0.25, generator=torch.Generator().manual_seed(1))
    everything = sample_pairs(source, source, None, max_pixels=10**7, holdout=0.25, generator=torch.Generator().manual_seed(1))
    strata = tg.match.pixels.colour_strata
    available = torch.bincount(strata(everything.train_source.reshape(3, -1)))
    drawn = torch.bincount(strata(pairs.train_source.reshape(3, -1)), minlength=len(available))
    assert drawn.sum() == 4096 and torch.all(drawn <= available)
    left = drawn < available  # strata with pixels left over
    assert drawn[left].max() - drawn[left].min() <= 1 and torch.all(drawn[~left] <= drawn[left].max())
    # the brightest stops hold a share of the fitting pixels far above their share of the picture
    luminance = tg.color.luminance(everything.train_source)
    bright = luminance > torch.quantile(luminance.flatten(), 0.99)
    assert (tg.color.luminance(pairs.train_source) > torch.quantile(luminance.flatten(), 0.99)).double().mean() > 5 * bright.double().mean()


@pytest.mark.parametrize("mode", tg.match.TONEMAP_CANDIDATES)
def test_bounded_controls_never_leave_their_ranges(mode):
    """Every control fitted by default, and every curve parameter of every candidate, pushed as far as the optimiser
    can push it: inside its range, accepted by the stages themselves, with a finite picture."""
    curve_table = tg.tonemap.TONE_MAPPERS[mode].controls
    grade = BoundedControls(tg.ColorGrade.controls, tg.match.GRADE_CONTROLS)
    curve = BoundedControls(curve_table, fittable_names(curve_table))
    image = torch.tensor([0.0, 1e-4, 0.18, 1.0, 60.0, 65504.0]).reshape(1, 1, 1, 6).expand(1, 3, 1, 6)
    for raw in (-1e4, -3.0, 0.0, 3.0, 1e4):
        for module in (grade, curve):
            with torch.no_grad():
                for parameter in module.raw.values():
                    parameter.fill_(raw)
            for name, value in module.values().items():
                low, high, _ = module.ranges[name]
                assert torch.all((value >= low) & (value <= high)), (name, raw, value)
        look = tg.PostFX(grade=grade.plain_values(digits=12), tonemap={"mode": mode, **curve.plain_values(digits=12)})
        assert torch.isfinite(look(image)).all(), raw
    assert grade.values()["lift"].shape == (4,) and grade.values()["split_shadows"].shape == (3,)


def test_known_look_is_matched_and_its_controls_recovered(exr_dir):
    source = scene(exr_dir)
    truth = dict(contrast=25.0, saturation=-20.0, temperature=15.0, hue_shift=10.0,
                 lift=(0.9, 1.0, 0.95, 0.03), gamma=(1.0, 1.0, 1.0, -0.1), gain=(1.0, 0.95, 0.9, 0.1),
                 split_shadows=(0.4, 0.5, 0.6), split_highlights=(0.6, 0.5, 0.4))
    target = tg.PostFX(grade=truth, tonemap="aces")(source[None])[0]
    result = tg.match_look(source, target, controls=tuple(truth), tonemaps="aces", max_pixels=2048, progress=False)
    assert result.errors["controls"]["p99.9"] <= 0.5, result.errors
    fitted = result.look.to_config()["grade"]
    # Contrast, saturation and hue shift each change the picture in a way no other control can; temperature
    # is partly interchangeable with the gain's colour and split toning, so it is only recovered roughly.
    assert fitted["contrast"] == pytest.approx(25.0, abs=1.5)
    assert fitted["saturation"] == pytest.approx(-20.0, abs=1.5)
    assert fitted["hue_shift"] == pytest.approx(10.0, abs=0.5)
    assert fitted["temperature"] == pytest.approx(15.0, abs=5.0)
    assert result.history[-1] < result.history[0] / 100


KNOWN_LOOKS = {
    "lift/gamma/gain": ({"lift": (0.9, 1.0, 0.95, 0.03), "gamma": (1.0, 0.9, 1.0, -0.1), "gain": (1.0, 0.95, 0.9, 0.1)}, "aces"),
    "split toning": ({"split_shadows": (0.4, 0.5, 0.6), "split_highlights": (0.6, 0.5, 0.4), "split_balance": 20.0}, "aces"),
    "hue shift and tint": ({"hue_shift": -25.0, "tint": 15.0, "saturation": 10.0}, "neutral"),
    "reinhard_extended's white point": ({"contrast": 10.0}, {"mode": "reinhard_extended", "white_point": 6.0}),
    "hable's white point and exposure bias": ({"contrast": 10.0}, {"mode": "hable", "white_point": 8.0, "exposure_bias": 1.5}),
}
"""Looks whose controls, fitted alone, are identifiable: no other fitted control has the same effect."""

# Stated tolerances, in each control's units: 0.05 of a -100..100 slider, 0.05 degree, 0.002 of a colour or
# trackball component (a fiftieth of a code at 8 bits), 0.5 % of a tone mapper's curve parameter.
TOLERANCES = {"split_balance": 0.05, "hue_shift": 0.05, "tint": 0.05, "saturation": 0.05, "contrast": 0.05}


@pytest.mark.parametrize("name", KNOWN_LOOKS)
def test_each_known_look_is_matched_and_its_controls_recovered(exr_dir, name):
    grade, tonemap = KNOWN_LOOKS[name]
    source = scene(exr_dir)
    target = tg.PostFX(grade=grade, tonemap=tonemap)(source[None])[0]
    mode = tonemap if isinstance(tonemap, str) else tonemap["mode"]
    result = tg.match_look(source, target, controls=tuple(grade), tonemaps=mode, max_pixels=2048, progress=False)
    assert result.errors["controls"]["p99.9"] <= 0.5, result.errors
    config = result.look.to_config()
    for control, value in grade.items():
        expected = np.atleast_1d(value)
        tolerance = TOLERANCES.get(control, 0.002)
        np.testing.assert_allclose(np.atleast_1d(config["grade"][control]), expected, rtol=0, atol=tolerance, err_msg=control)
    curve = {} if isinstance(tonemap, str) else {k: v for k, v in tonemap.items() if k != "mode"}
    for parameter, value in curve.items():
        assert config["tonemap"][parameter] == pytest.approx(value, rel=0.005), (parameter, config)


def test_tone_mapper_is_chosen_and_identifiable_controls_recovered_closely(exr_dir):
    source = scene(exr_dir, "CandleGlass.exr")
    truth = dict(post_exposure=0.5, temperature=-20.0, contrast=15.0, saturation=25.0)
    target = tg.PostFX(grade=truth, tonemap="agx")(source[None])[0]
    result = tg.match_look(source, target, controls=tuple(truth), tonemaps=("neutral", "agx", "aces"), max_pixels=1024,
                           progress=False)
    assert result.look.to_config()["tonemap"] == {"mode": "agx"}
    assert min(result.candidates, key=result.candidates.get) == "agx"
    fitted = result.look.to_config()["grade"]
    for name, value in truth.items():
        assert fitted[name] == pytest.approx(value, abs=0.02 * (1.0 if name == "post_exposure" else 10.0)), (name, fitted)
    assert result.errors["controls"]["p99.9"] <= 0.1


class RecordedBar:
    """Stands in for tqdm: records each bar's description, total, updates and latest loss."""

    bars = []

    def __init__(self, total, desc, disable, leave):
        self.total, self.desc, self.disable, self.done, self.postfix = total, desc, disable, 0, None
        RecordedBar.bars.append(self)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def update(self, n=1):
        self.done += n

    def set_postfix(self, loss, refresh):
        self.postfix = loss


def test_progress_bars_and_loss_history_by_phase(monkeypatch):
    for module in (tg.match.solver, tg.match.residual):
        monkeypatch.setattr(module, "tqdm", RecordedBar)
    RecordedBar.bars = []
    source = torch.rand(3, 24, 24, dtype=torch.float64, generator=torch.Generator().manual_seed(4)) * 4
    target = tg.PostFX(grade={"contrast": 20, "lift": (1.0, 0.9, 0.9, 0.05)}, tonemap="aces")(source[None])[0]
    result = tg.match_look(source, target, controls=("contrast", "lift"), tonemaps=("neutral", "aces"), screen_steps=5,
                           steps=7, residual=True, residual_size=5, residual_steps=6)
    bars = [(bar.desc, bar.total, bar.disable) for bar in RecordedBar.bars]
    # each candidate: the global controls, then every control (lift is not global); then the finalists, in order
    screening = [(f"screen {mode}", 5, None) for mode in ("neutral", "aces") for _ in range(2)]
    assert bars[:4] == screening and bars[-1] == ("residual 5³", 6, None)
    assert bars[4:-1] == [(f"match {mode}", 7, None) for mode in result.finalists for _ in range(2)]
    assert all(1 <= bar.done <= bar.total for bar in RecordedBar.bars)  # Levenberg-Marquardt may stop early
    assert all(float(bar.postfix) >= 0 for bar in RecordedBar.bars)  # the latest loss is shown
    phases = dict(result.phases)
    assert list(phases) == ["global controls", "every control", "residual Adam", "residual L-BFGS"]
    finals = [bar for bar in RecordedBar.bars if bar.desc == f"match {result.look.to_config()['tonemap']['mode']}"]
    # the loss where each phase starts, then each trial
    assert [phases["global controls"], phases["every control"]] == [bar.done + 1 for bar in finals]
    assert phases["residual Adam"] == 3 and sum(phases.values()) == len(result.history)
    assert set(result.candidates) == {"neutral", "aces"} and min(result.finalists.values()) <= min(result.candidates.values())
    RecordedBar.bars = []
    tg.match_look(source, target, controls=("contrast",), tonemaps="neutral", steps=2, progress=False)
    assert [bar.disable for bar in RecordedBar.bars] == [True]


def test_scene_referred_target_from_two_pairs_with_masks(exr_dir, device):
    source = scene(exr_dir).to(device)
    target = tg.ColorGrade(contrast=-20.0, saturation=30.0)(source[None])[0]
    mask = torch.rand(source.shape[1:]) < 0.5  # on the CPU, whatever the images' device
    target[:, ~mask.to(device)] = 0.0  # outside the mask the "target" is unrelated to the look
    half = source.shape[2] // 2
    sources, targets = [source[..., :half], source[..., half:]], [target[..., :half], target[..., half:]]
    result = tg.match_look(sources, targets, stages=("grade",), mask=[mask[:, :half], mask[:, half:]],
                           controls=("contrast", "saturation"), max_pixels=1024, progress=False)
    assert result.look.to_config() == {"grade": {"contrast": pytest.approx(-20.0, abs=0.01), "saturation": pytest.approx(30.0, abs=0.01)}}
    assert result.errors["controls"]["p99.9"] <= 0.1


def test_opencolorio_look_is_matched_by_controls_and_a_residual_lut(exr_dir, tmp_path):
    source = scene(exr_dir, step=8)
    target = ocio_look(source)
    result = tg.match_look(source, target, controls=("post_exposure", "color_filter", "contrast", "saturation"),
                           tonemaps="aces_reference", steps=60, max_pixels=2048, residual=True,
                           residual_steps=100, progress=False)
    assert result.errors["residual"]["p99.9"] <= 1.0, result.errors
    assert result.errors["residual"]["p99.9"] < result.errors["controls"]["p99.9"]
    assert result.errors["residual"]["delta_e_2000"] < result.errors["controls"]["delta_e_2000"]
    table = result.residual.lut.table.detach()
    assert monotonicity(table) < 1e-6
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)  # the report is checked below
        written = {suffix: result.write_lut(tmp_path / f"look{suffix}", size=65) for suffix in (".cube", ".clf")}
    held_out = result.pixels.test_target.reshape(3, -1)
    lut = tg.io.read_cube(tmp_path / "look.cube")
    with torch.no_grad():
        by_cube = match_errors(held_out, lut(result.pixels.test_source).reshape(3, -1))
    # OpenColorIO applies the CLF: an independent reading of the file the look wrote
    by_clf = ocio_apply(ocio_processor(tmp_path / "look.clf", "tetrahedral"), result.pixels.test_source)
    by_clf = match_errors(held_out, by_clf.reshape(3, -1).double())
    for suffix, measured in ((".cube", by_cube), (".clf", by_clf)):
        report = written[suffix].pop("report")
        assert isinstance(report, ErrorReport) and report.colours > 0
        assert written[suffix] == pytest.approx({"size": 65, **measured}, abs=0.01), suffix
        assert measured["p99.9"] <= 1.0, (suffix, measured)  # 65³ holds the whole look within a code
    with pytest.raises(ValueError, match=r"\.cube or \.clf"):
        result.write_lut(tmp_path / "look.3dl")


def test_residual_lut_starts_as_identity_and_bad_inputs_raise():
    display = torch.rand(1, 3, 8, 8, dtype=torch.float64)
    assert torch.allclose(ResidualLUT(9)(display), display, atol=1e-9)
    source = torch.rand(3, 8, 8)
    with pytest.raises(ValueError, match="differ in size"):
        tg.match_look(source, torch.rand(3, 8, 9), progress=False)
    with pytest.raises(ValueError, match="unknown tone mapping mode"):
        tg.match_look(source, source, tonemaps="filmic2", progress=False)
    with pytest.raises(ValueError, match="not a numeric control"):
        tg.match_look(source, source, controls=("hue_vs_hue",), tonemaps="aces", progress=False)
    with pytest.raises(ValueError, match="residual=True needs"):
        tg.match_look(source, source, stages=("grade",), residual=True, progress=False)
    with pytest.raises(ValueError, match="stages must be"):
        tg.match_look(source, source, stages=("bloom",), progress=False)
    with pytest.raises(ValueError, match="keep must be an integer of at least 1, got 0"):
        tg.match_look(source, source, keep=0, progress=False)
