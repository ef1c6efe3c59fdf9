"""Eye adaptation as the engines meter it: histogram metering, metering masks, limits and compensation in stops,
the compensation curve and fixed exposure.

References are float64 numpy implementations written here from the anchors' documentation: HDRP's Automatic
Histogram (bins over the metering range, the cumulative share of each bin inside the percentile band, the band
averaged), its Center Weighted and Spot masks (``1 - saturate(d / s)``, ``1 - saturate(d - 0.075 s)``), Bevy's and
Unreal's compensation curve (piecewise linear, constant past its ends: ``np.interp``); and invariants (scaling
the scene by ``2^k`` moves the metered stops by ``k`` inside the limits and not at all outside).
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.exposure import HISTOGRAM_BINS, histogram_band_average, meter_luminance, metering_weights
from torchgrade.exposure.metering import HISTOGRAM_BLOCK, block_stops
from torchgrade.functional import auto_exposure

SAMPLES = Path(__file__).resolve().parents[3] / "shared" / "data" / "exr"
PHOTOGRAPHS = ["Desk", "CandleGlass", "GoldenGate", "Garden", "Carrots"]
REC709 = np.array([0.2126729, 0.7151522, 0.0721750])
GREY = 0.18


def luminance64(image: torch.Tensor) -> np.ndarray:
    """Rec.709 luminance of ``(1, 3, H, W)`` in float64 numpy, negatives clipped, ``(H, W)``."""
    return np.maximum(np.einsum("chw,c->hw", image[0].double().numpy(), REC709), 0.0)


def band_shares(stops: np.ndarray, weights: np.ndarray, low: float, high: float, percents=(40.0, 90.0)):
    """The histogram of the anchors: each pixel's bin over ``[low, high]`` (values clamped to it) and each bin's
    fraction inside the percentile band, in float64."""
    values = np.clip(stops, low, high)
    bins = np.minimum(np.floor((values - low) / (high - low) * HISTOGRAM_BINS), HISTOGRAM_BINS - 1).astype(int)
    counts = np.bincount(bins.ravel(), weights.ravel(), minlength=HISTOGRAM_BINS)
    total = counts.sum()
    end = np.cumsum(counts) / total
    start = end - counts / total
    inside = np.clip(np.minimum(end, percents[1] / 100) - np.maximum(start, percents[0] / 100), 0, None)
    return values, bins, inside, counts


def engine_histogram_stops(stops, weights, low=-8.0, high=8.0, percents=(40.0, 90.0)) -> float:
    """HDRP's and Bevy's band average: the bins' centres weighted by their fraction inside the band."""
    _, _, inside, _ = band_shares(stops, weights, low, high, percents)
    centres = low + (np.arange(HISTOGRAM_BINS) + 0.5) * (high - low) / HISTOGRAM_BINS
    return float((inside * centres).sum() / inside.sum())


def pixel_histogram_stops(stops, weights, low=-8.0, high=8.0, percents=(40.0, 90.0)) -> float:
    """The same band, averaging the pixels' own values: each pixel weighted by its bin's fraction per unit weight."""
    values, bins, inside, counts = band_shares(stops, weights, low, high, percents)
    per_weight = np.where(counts > 0, inside * counts.sum() / np.where(counts > 0, counts, 1), 0.0)
    chosen = per_weight[bins] * weights
    return float((chosen * values).sum() / chosen.sum())


def block_means(stops: np.ndarray, block: int, low: float = -8.0, high: float = 8.0):
    """``stops`` clamped to ``[low, high]``, averaged over squares of ``block`` pixels (those cut by the right and bottom
    edges over their own pixels), and each square's share of ``block²`` pixels, in float64."""
    height, width = stops.shape
    padded = np.full((-(-height // block) * block, -(-width // block) * block), np.nan)
    padded[:height, :width] = np.clip(stops, low, high)
    blocks = padded.reshape(padded.shape[0] // block, block, padded.shape[1] // block, block)
    return np.nanmean(blocks, axis=(1, 3)), (~np.isnan(blocks)).sum(axis=(1, 3)) / block**2


def counted_stops(image: torch.Tensor, mask: str, block: int, low: float = -8.0, high: float = 8.0):
    """What the histogram counts of ``image``: the :func:`block_means` of its stops, and their weights (``mask``'s
    weights at the blocks times the blocks' shares)."""
    means, shares = block_means(stops_of(image), block, low, high)
    weights = np.ones(means.shape) if mask == "average" else metering_weights(mask, torch.zeros(means.shape)).double().numpy()
    return means, weights * shares


def sample(name: str, size: int = 160) -> torch.Tensor:
    """A sample image as ``(1, 3, h, w)`` linear Rec.709, area-downsampled to ``size`` pixels wide (exact enough:
    the reference and the code under test see the same pixels)."""
    image = tg.io.read_exr(SAMPLES / f"{name}.exr", to_rec709=True)[:3].unsqueeze(0)
    height = max(1, round(image.shape[-2] * size / image.shape[-1]))
    return torch.nn.functional.interpolate(torch.nan_to_num(image, 0.0, 0.0, 0.0), size=(height, size), mode="area").double()


def stops_of(image: torch.Tensor) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.log2(luminance64(image) / GREY)


def centre_distance(height: int, width: int) -> np.ndarray:
    rows = np.arange(height) + 0.5 - height / 2
    columns = np.arange(width) + 0.5 - width / 2
    return np.hypot(rows[:, None], columns[None, :])


# ---------------------------------------------------------------- histogram against the anchors' algorithm


@pytest.mark.parametrize("name", PHOTOGRAPHS)
@pytest.mark.parametrize("mask", ["average", "center", "spot"])
@pytest.mark.parametrize("block", [1, 2, 3])
def test_histogram_metering_matches_the_float64_references(name, mask, block):
    """The band average of the values counted (every pixel's, or each block's mean) to 1e-6 stops; the engines' average
    of bin centres to half a bin."""
    image = sample(name)
    values, weights = counted_stops(image, mask, block)
    metered = meter_luminance(image, "histogram", mask=mask, block=block)
    stops = math.log2(float(metered) / GREY)
    assert abs(stops - pixel_histogram_stops(values, weights)) < 1e-6
    assert abs(stops - engine_histogram_stops(values, weights)) <= 0.5 * 16 / HISTOGRAM_BINS


@pytest.mark.parametrize("name", PHOTOGRAPHS)
def test_counting_blocks_moves_the_photographs_metering_by_at_most_a_twentieth_of_a_stop(name):
    """The histogram's 2x2 blocks against every pixel (:data:`HISTOGRAM_BLOCK`), each sample photograph at its full
    size, with every mask: within 0.05 stops."""
    image = tg.io.read_exr(SAMPLES / f"{name}.exr", to_rec709=True)[:3].unsqueeze(0)
    for mask in tg.exposure.METERING_MASKS:
        every_pixel = float(meter_luminance(image, "histogram", mask=mask, block=1))
        blocks = float(meter_luminance(image, "histogram", mask=mask, block=2))
        assert HISTOGRAM_BLOCK == 1 and abs(math.log2(blocks / every_pixel)) <= 0.05, mask


@pytest.mark.parametrize("size", [(1, 1), (5, 7), (37, 50)])
@pytest.mark.parametrize("block", [2, 3, 4])
def test_blocks_weighted_by_their_shares_average_to_the_frame_mean(size, block):
    """Every pixel counts once: the blocks the frame's edges cut weigh what they hold."""
    stops = torch.randn(1, 1, *size, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 4
    means, shares = block_stops(stops, -8.0, 8.0, block)
    assert float((means[0, 0] * shares).sum() / shares.sum()) == pytest.approx(float(stops.clamp(-8, 8).mean()), rel=1e-12)
    assert shares.shape == means.shape[-2:] == tuple(-(-side // block) for side in size)


@pytest.mark.parametrize("threads", [1, 3, 16])
@pytest.mark.parametrize("mask", ["average", "center"])
def test_histogram_metering_on_any_thread_count_matches_the_float64_reference(threads, mask):
    """A batch of two frames 105 rows high, their columns counted into eight tables
    (:data:`~torchgrade.exposure.metering.HISTOGRAM_TABLES`), on 1, 3 and 16 threads: each frame metered, every pixel
    counted, as the reference does, to 1e-6 stops."""
    frames = torch.cat([sample("Desk")[..., :105, :], sample("GoldenGate")[..., :105, :]])
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        metered = meter_luminance(frames, "histogram", mask=mask, block=1)
    finally:
        torch.set_num_threads(before)
    for image, value in zip(frames.split(1), metered.tolist()):
        weights = np.ones(image.shape[-2:]) if mask == "average" else metering_weights(mask, image).double().numpy()
        assert abs(math.log2(value / GREY) - pixel_histogram_stops(stops_of(image), weights)) < 1e-6


def test_histogram_percent_band_and_range_are_the_controls():
    image = sample("Desk")
    for percents, (low, high) in [((10.0, 90.0), (-8.0, 8.0)), ((60.0, 99.0), (-4.0, 2.0)), ((0.0, 100.0), (-12.0, 12.0))]:
        metered = meter_luminance(image, "histogram", stop_range=(low, high), percents=percents)
        expected = pixel_histogram_stops(*counted_stops(image, "average", HISTOGRAM_BLOCK, low, high), low, high, percents)
        assert abs(math.log2(float(metered) / GREY) - expected) < 1e-6, percents


def test_a_uniform_frame_meters_its_own_luminance_in_every_mode():
    for value in [1e-3, 0.05, 0.18, 3.0, 40.0]:
        frame = torch.full((1, 3, 5, 7), value, dtype=torch.float64)
        for metering in tg.exposure.METERING_MODES:
            for mask in tg.exposure.METERING_MASKS:
                assert float(meter_luminance(frame, metering, mask=mask)) == pytest.approx(value, rel=1e-6), (metering, mask)  # the weights sum to 1 within 1e-7


def test_histogram_gradient_is_the_share_of_each_chosen_pixel():
    """d(band average)/d(pixel) is the pixel's share of the band (0 outside it): the choice carries no gradient."""
    image = sample("Garden", 64)
    stops = torch.tensor(stops_of(image)).clamp(-8, 8).reshape(1, 1, *image.shape[-2:]).requires_grad_(True)
    histogram_band_average(stops, None, -8.0, 8.0, 40.0, 90.0).sum().backward()
    values, bins, inside, counts = band_shares(stops.detach()[0, 0].numpy(), np.ones(image.shape[-2:]), -8.0, 8.0)
    chosen = np.where(counts > 0, inside / np.where(counts > 0, counts, 1), 0.0)[bins]
    np.testing.assert_allclose(stops.grad[0, 0].numpy(), chosen / chosen.sum(), atol=1e-12)
    assert (stops.grad == 0).float().mean() > 0.4  # the darkest 40 % and brightest 10 % are not metered


# ---------------------------------------------------------------- masks


@pytest.mark.parametrize("size", [(1, 1), (7, 5), (48, 80)])
def test_center_and_spot_weights_follow_hdrp(size):
    height, width = size
    distance, half_extent = centre_distance(height, width), (height + width) / 2
    like = torch.zeros(1, 3, height, width, dtype=torch.float64)
    np.testing.assert_allclose(metering_weights("center", like).numpy(), 1 - np.clip(distance / half_extent, 0, 1), atol=1e-12)
    np.testing.assert_allclose(metering_weights("spot", like).numpy(), 1 - np.clip(distance - 0.075 * half_extent, 0, 1), atol=1e-12)


@pytest.mark.parametrize("mask", ["center", "spot", "user"])
def test_weighted_mean_and_log_metering_match_numpy(mask):
    image = sample("GoldenGate", 96)
    if mask == "user":
        weights = np.random.default_rng(0).random(image.shape[-2:])
        stage_mask = torch.tensor(weights)  # the frame's own size: resampling leaves it as it is
    else:
        weights, stage_mask = metering_weights(mask, image).numpy(), mask
    lum = luminance64(image)
    assert float(meter_luminance(image, "mean", mask=stage_mask)) == pytest.approx((weights * lum).sum() / weights.sum(), rel=1e-9)
    log_average = math.exp((weights * np.log(lum + 1e-4)).sum() / weights.sum()) - 1e-4
    assert float(meter_luminance(image, "log", mask=stage_mask)) == pytest.approx(log_average, rel=1e-9)


def test_spot_metering_reads_the_centre_and_a_user_mask_reads_its_region():
    frame = torch.full((1, 3, 90, 160), 0.02)
    frame[..., 35:55, 70:90] = 1.5  # a bright subject in the middle, wider than the spot
    assert float(meter_luminance(frame, "mean", mask="spot")) == pytest.approx(1.5, rel=1e-6)
    assert float(meter_luminance(frame, "mean", mask="average")) < 0.1
    corner = torch.zeros(9, 16)
    corner[:3, :4] = 1.0
    assert float(meter_luminance(frame, "histogram", mask=corner)) == pytest.approx(0.02, rel=1e-5)


def test_a_mask_the_frame_gives_no_weight_meters_the_whole_frame():
    frame = torch.rand(1, 3, 4, 4, dtype=torch.float64) + 0.1
    empty_here = torch.zeros(64, 64)
    empty_here[0, 0] = 1.0  # resampled to 4x4, nothing of it is left
    assert float(meter_luminance(frame, "mean", mask=empty_here)) == pytest.approx(float(meter_luminance(frame, "mean")), rel=1e-12)


# ---------------------------------------------------------------- limits, compensation, curve, fixed exposure


@pytest.mark.parametrize("metering", ["mean", "histogram"])
def test_scaling_the_scene_by_2_to_the_k_moves_the_metered_stops_by_k_inside_the_limits(metering):
    image = sample("Carrots").clamp_min(0.18 * 2 ** -4)  # every pixel inside the histogram's range at every k
    layer = tg.AutoExposure(metering=metering, min_ev=-1.5, max_ev=1.5)
    _, base = layer.frame(image, None, 0.0)
    base_stops = math.log2(float(base) / GREY)
    assert -1.5 < base_stops < 1.5
    for k in [-3, -1, 1, 2]:
        _, adapted = layer.frame(image * 2.0 ** k, None, 0.0)
        expected = min(max(base_stops + k, -1.5), 1.5)
        assert math.log2(float(adapted) / GREY) == pytest.approx(expected, abs=1e-5), k
        stops = float(layer.exposure_stops(adapted))
        assert stops == pytest.approx(-expected, abs=1e-5)


def test_log_metering_moves_by_k_where_the_scene_is_far_above_its_delta():
    image = sample("Carrots").clamp_min(0.01)
    base = float(meter_luminance(image, "log"))
    for k in [-2, 3]:
        assert math.log2(float(meter_luminance(image * 2.0 ** k, "log")) / base) == pytest.approx(k, abs=0.02)


def test_compensation_and_the_curve_add_stops_to_the_exposure():
    curve = ((-8.0, -4.0), (-2.0, 0.0), (4.0, 1.0))
    layer = tg.AutoExposure(metering="mean", compensation=0.5, compensation_curve=curve)
    for value in [0.18 * 2 ** -7, 0.18 * 2 ** -5, 0.18, 0.18 * 2 ** 3, 0.18 * 2 ** 6]:
        frame = torch.full((1, 3, 4, 4), value, dtype=torch.float64)
        exposed, adapted = layer.frame(frame, None, 0.0)
        metered_stops = math.log2(value / GREY)
        expected = -metered_stops + 0.5 + np.interp(metered_stops, [p[0] for p in curve], [p[1] for p in curve])
        # Rec.709's weights sum to 1 within 1e-7, so a grey frame meters its value within 1.5e-7 stops
        assert float(layer.exposure_stops(adapted)) == pytest.approx(expected, abs=1e-6)
        assert float(exposed.mean()) == pytest.approx(value * 2 ** expected, rel=1e-6)


def test_the_curve_is_np_interp_with_constant_ends():
    curve = ((-6.0, -2.0), (-1.0, 0.5), (0.0, 0.0), (5.0, 2.0))
    stops = torch.linspace(-12, 12, 97, dtype=torch.float64)
    expected = np.interp(stops.numpy(), [p[0] for p in curve], [p[1] for p in curve])
    np.testing.assert_allclose(tg.exposure.compensation_at(curve, stops).numpy(), expected, atol=1e-12)


def test_fixed_exposure_meters_nothing_and_scales_by_2_to_the_stops():
    image = sample("Desk", 64)
    layer = tg.AutoExposure(metering="histogram", fixed_exposure=-1.25, compensation=0.25,
                            compensation_curve=((-8.0, -4.0), (0.0, 0.0)))
    exposed, adapted = layer.frame(image, None, 0.0)
    torch.testing.assert_close(exposed, image * 2.0 ** -1.0, rtol=1e-12, atol=0)
    assert float(layer.exposure_stops(adapted)) == pytest.approx(-1.0, abs=1e-12)
    # from a state, the fixed target is approached at the adaptation's speed: target + (state - target) e^(-dt)
    target = GREY * 2.0 ** 1.25
    _, moved = layer.frame(image, torch.tensor([0.7], dtype=torch.float64), 0.5)
    assert float(moved) == pytest.approx(target + (0.7 - target) * math.exp(-0.5), rel=1e-12)


def test_limits_clamp_the_metered_stops_and_the_adaptation():
    layer = tg.AutoExposure(metering="histogram", min_ev=-2.0, max_ev=3.0, speed=1.0)
    dark, bright = (torch.full((1, 3, 8, 8), GREY * 2.0 ** s) for s in (-6, 7))
    _, adapted = layer.frame(dark, None, 0.0)
    assert math.log2(float(adapted) / GREY) == pytest.approx(-2.0, abs=1e-6)
    _, adapted = layer.frame(bright, adapted, 10.0)
    assert math.log2(float(adapted) / GREY) == pytest.approx(3.0, abs=1e-4)


def test_per_sample_controls_equal_one_frame_at_a_time():
    images = torch.cat([sample("Desk", 64)[..., :32, :], sample("Garden", 64)[..., :32, :]])
    per_sample = dict(compensation=torch.tensor([0.5, -1.0]), min_ev=torch.tensor([-1.0, -3.0]), max_ev=torch.tensor([1.0, 2.5]),
                      low_percent=torch.tensor([40.0, 10.0]), high_percent=torch.tensor([90.0, 99.0]))
    exposed, adapted = tg.AutoExposure(metering="histogram", metering_mask="center", **per_sample).frame(images, None, 0.0)
    for i in range(2):
        one = tg.AutoExposure(metering="histogram", metering_mask="center", **{k: float(v[i]) for k, v in per_sample.items()})
        alone, state = one.frame(images[i:i + 1], None, 0.0)
        torch.testing.assert_close(exposed[i:i + 1], alone, rtol=1e-12, atol=0)
        torch.testing.assert_close(adapted[i:i + 1], state, rtol=1e-12, atol=0)


def test_gradients_reach_the_image_and_every_continuous_control():
    image = sample("GoldenGate", 48).float().requires_grad_(True)
    controls = {name: torch.tensor(value, requires_grad=True) for name, value in
                dict(compensation=0.3, min_ev=-6.0, max_ev=6.0, middle_grey=0.18).items()}
    exposed, _ = auto_exposure(image, None, metering="histogram", metering_mask="center", **controls)
    exposed.sum().backward()
    assert image.grad.isfinite().all() and image.grad.abs().sum() > 0
    # the exposure operator scales by 2^compensation: d(sum)/d(compensation) = ln 2 * sum
    assert float(controls["compensation"].grad) == pytest.approx(math.log(2) * float(exposed.sum()), rel=1e-4)
    # the metered value lies inside the limits, so they carry no gradient; middle grey cancels against the meter
    assert float(controls["min_ev"].grad) == 0.0 and float(controls["max_ev"].grad) == 0.0


def test_a_limit_that_binds_carries_the_gradient():
    frame = torch.full((1, 3, 4, 4), GREY * 2.0 ** -5)
    min_ev = torch.tensor(-2.0, requires_grad=True)
    exposed, _ = auto_exposure(frame, None, metering="mean", min_ev=min_ev)
    exposed.sum().backward()  # exposed = frame * 2^-min_ev
    assert float(min_ev.grad) == pytest.approx(-math.log(2) * float(exposed.sum()), rel=1e-5)


# ---------------------------------------------------------------- the stage: configs, checks, the command line


def test_every_new_control_round_trips_through_json():
    mask = [[0.0, 1.0, 0.0], [1.0, 2.0, 1.0]]
    layer = tg.AutoExposure(metering="histogram", metering_mask=mask, low_percent=20.0, high_percent=95.0, min_ev=-4.0, max_ev=5.0,
                            compensation=0.5, compensation_curve=[[-8, -3], [0, 0]], fixed_exposure=None, speed_to_light=3.0)
    config = json.loads(json.dumps(layer.to_config()))
    assert config["metering_mask"] == mask and config["compensation_curve"] == [[-8.0, -3.0], [0.0, 0.0]]
    again = tg.AutoExposure.from_config(config)
    image = sample("Desk", 64).float()
    torch.testing.assert_close(again.frame(image, None, 0.0)[0], layer.frame(image, None, 0.0)[0], rtol=0, atol=0)


@pytest.mark.parametrize("controls, message", [
    (dict(metering_mask="matrix"), "metering_mask"),
    (dict(metering_mask=[[1.0, -1.0]]), "metering_mask must hold finite weights >= 0"),
    (dict(metering_mask=[[0.0, 0.0]]), "at least one of them > 0"),
    (dict(metering_mask=torch.ones(2, 2, 2)), "2-D"),
    (dict(compensation_curve=[[0, 0], [-1, 1]]), "must increase"),
    (dict(compensation_curve=[[0, 0]]), "2 to 64 points"),
    (dict(compensation_curve=[[0, 0], [1, 100]]), "must lie in"),
    (dict(min_ev=2.0, max_ev=1.0), "min_ev"),
    (dict(metering="histogram", low_percent=90.0, high_percent=40.0), "low_percent"),
    (dict(metering="histogram", min_ev=1.0, max_ev=1.0), "min_ev"),
    (dict(compensation=40.0), "compensation must lie in"),
    (dict(fixed_exposure=float("nan")), "fixed_exposure"),
])
def test_bad_controls_are_refused_by_name(controls, message):
    with pytest.raises(ValueError, match=message):
        tg.AutoExposure(**controls)


def test_the_cinematic_look_and_the_demo_are_one_look():
    from torchgrade.cli.demo import DEFAULT_LOOK

    cinematic = json.loads((Path(__file__).resolve().parents[2] / "export" / "looks" / "cinematic.json").read_text())
    assert json.loads(json.dumps(DEFAULT_LOOK)) == cinematic


def test_grade_takes_the_eye_adaptation_flags(tmp_path, capsys):
    from torchgrade.cli import main

    output = tmp_path / "desk.png"
    assert main(["grade", str(SAMPLES / "Desk.exr"), "-o", str(output), "--metering", "histogram", "--metering-mask", "center",
                 "--ev-limits", "-3", "3", "--compensation", "0.5", "--histogram-percent", "10", "95", "--contrast", "10"]) == 0
    assert "AutoExposure -> ColorGrade -> ToneMap" in capsys.readouterr().out and output.stat().st_size > 0
    with pytest.raises(SystemExit):
        main(["grade", str(SAMPLES / "Desk.exr"), "-o", str(tmp_path / "b.png"), "--metering", "median"])
    config = Path(__file__).resolve().parents[2] / "export" / "looks" / "cinematic.json"
    assert main(["grade", str(SAMPLES / "Desk.exr"), "-o", str(tmp_path / "c.png"), "--config", str(config), "--fixed-exposure", "1"]) != 0
    assert "not both" in capsys.readouterr().err


# ---------------------------------------------------------------- ONNX: onnxruntime and OpenVINO


EXPORTED = {
    "histogram-center-curve": dict(metering="histogram", metering_mask="center", min_ev=-3.0, max_ev=3.0, compensation=0.5,
                                   compensation_curve=((-8.0, -3.0), (-1.0, 0.0)), speed_to_light=3.0, speed_to_dark=1.0),
    "histogram-spot-band": dict(metering="histogram", metering_mask="spot", low_percent=10.0, high_percent=98.0),
    "log-user-mask": dict(metering="log", metering_mask=torch.tensor([[0.0, 1.0, 0.0], [1.0, 3.0, 1.0]])),
    "fixed": dict(fixed_exposure=-1.5, compensation=0.25),
}


@pytest.mark.parametrize("name", EXPORTED)
def test_exported_exposure_matches_pytorch_on_onnxruntime_and_openvino(name, tmp_path):
    """One file, two frame sizes (the sizes stay symbolic: masks and bins are built from the frame's shape), both runtimes
    at float32, from a first frame and from a state."""
    from torchgrade.onnx import RUNTIMES, export, feeds, graph_inputs, reference, session

    look = tg.PostFX(exposure=EXPORTED[name], tonemap="aces").eval()
    path = export(look, tmp_path / f"{name}.onnx")
    frames = [sample("GoldenGate", 120).float(), sample("Desk", 72).float()]
    for runtime in RUNTIMES:
        runner = session(path, runtime, "f32")
        for frame in frames:
            inputs = graph_inputs(look, frame)
            for output, expected in zip(runner.run(None, feeds(runner, look, inputs)), reference(look, inputs)):
                assert float(np.abs(output - expected.numpy()).max()) <= 1e-4 * max(1.0, float(expected.abs().max())), (name, runtime)


def test_the_histogram_block_is_a_control_checked_at_every_door_and_kept_in_the_config():
    image = sample("Garden", 96)
    for door in (lambda: tg.AutoExposure(histogram_block=0), lambda: tg.functional.meter_luminance(image, "histogram", block=17),
                 lambda: tg.functional.auto_exposure(image, histogram_block=2.5)):
        with pytest.raises(ValueError, match="histogram_block must be an integer in"):
            door()
    stage = tg.AutoExposure(metering="histogram", histogram_block=3)
    assert tg.AutoExposure(**stage.to_config()).histogram_block == 3
    _, adapted = stage.frame(image, None, 0.0)
    assert float(adapted) == pytest.approx(float(meter_luminance(image, "histogram", block=3)), rel=1e-9)
    assert float(adapted) != pytest.approx(float(meter_luminance(image, "histogram", block=1)), rel=1e-6)
