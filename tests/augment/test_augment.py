"""RandomPostFX: the batched random layer against the library's deterministic layers applied one sample
at a time with the sampled parameters, plus reproducibility, replay, p, same_on_batch and bounds."""

import contextlib
import pickle
import signal

import pytest
import torch

import torchgrade as tg
from torchgrade.color import linear_to_srgb, srgb_to_linear

GRADE_RANGES = dict(
    post_exposure=(-1.0, 1.0),
    temperature=(-30.0, 30.0),
    tint=(-30.0, 30.0),
    contrast=(-40.0, 40.0),
    split_shadows=(0.2, 0.8),
    split_highlights=(0.3, 0.7),
    split_balance=(-50.0, 50.0),
    hue_shift=(-90.0, 90.0),
    saturation=(-50.0, 50.0),
)
BLOOM_RANGES = dict(bloom_threshold=(0.5, 1.2), bloom_intensity=(0.2, 2.0), bloom_scatter=(0.3, 0.9))
MODES = ("neutral", "aces", "reinhard", "none")
FULL = dict(GRADE_RANGES, **BLOOM_RANGES, bloom_mode="scattering", tonemap=MODES)


def hdr_batch(batch=6, size=32, dtype=torch.float64, seed=1, device=None):
    """Scene-referred images: a smooth ramp up to ~8 with a few bright glints that bloom."""
    generator = torch.Generator().manual_seed(seed)
    images = torch.rand(batch, 3, size, size, generator=generator, dtype=dtype) ** 3 * 8.0
    images[:, :, size // 3, size // 2] = 50.0
    return images.to(device)


def seeded(seed):
    return torch.Generator().manual_seed(seed)


def reference_sample(image, params, i, layer):
    """Sample ``i`` through tg.Bloom, tg.ColorGrade and tg.ToneMap with its sampled parameters (a skipped sample
    through the tone mapper alone)."""
    x = image[i : i + 1]
    if not params["batch_prob"][i] and "tonemap" not in params:
        return x
    if layer.input_space == "srgb":
        x = srgb_to_linear(x)
    bloom = {name[len("bloom_") :]: params[name][i].item() for name in BLOOM_RANGES if name in params}
    if bloom and params["batch_prob"][i]:
        x = tg.Bloom(mode=layer.bloom_mode, **bloom)(x)
    grade = {name: params[name][i].tolist() for name in GRADE_RANGES if name in params}
    if params["batch_prob"][i]:
        x = tg.ColorGrade(aces=layer.aces, **grade)(x)
    if "tonemap" in params:
        x = tg.ToneMap(layer.tonemap[params["tonemap"][i]])(x)
    if layer.input_space == "srgb":
        x = linear_to_srgb(x).clamp(0.0, 1.0)
    return x


def assert_matches_per_sample(layer, images, out):
    params = layer.last_params
    for i in range(images.shape[0]):
        torch.testing.assert_close(out[i : i + 1], reference_sample(images, params, i, layer), atol=1e-9, rtol=1e-9)


def test_full_set_matches_per_sample_layers(device):
    layer = tg.RandomPostFX(**FULL)
    images = hdr_batch(batch=8, device=device)
    out = layer(images, generator=seeded(0))
    assert set(layer.last_params["tonemap"].tolist()) == {0, 1, 2, 3}, "the seed should draw every mode"
    assert_matches_per_sample(layer, images, out)


@pytest.mark.parametrize("input_space", ["linear", "srgb"])
def test_a_batch_larger_than_a_strip_is_graded_in_strips_as_it_is_whole(input_space, monkeypatch):
    """Without bloom a CPU batch runs on strips of rows (each strip's intermediates in cache): the same values as the
    whole batch at once (a device's policy: float32 rounding, vectorised loops round their tails apart), a tone mapper
    chosen per sample included."""
    from torchgrade.runtime import policy, strips

    layer = tg.RandomPostFX(**GRADE_RANGES, tonemap=MODES, p=0.7, input_space=input_space)
    images = torch.rand(6, 3, 160, 200, generator=seeded(7)) * (1.0 if input_space == "srgb" else 6.0)
    assert images.numel() > 3 * tg.runtime.policy_for(images.device).strip_pixels  # more than one strip
    params = layer.sample_params(6, seeded(8))
    stripped = layer(images, params=params)
    monkeypatch.setattr(strips, "policy_for", lambda device: policy.WHOLE_FRAMES)
    whole = layer(images, params=params)
    torch.testing.assert_close(stripped, whole, rtol=1e-5, atol=1e-5)
    assert_matches_per_sample(layer, images.double(), layer(images.double(), params=params))


def test_aces_grade_matches_per_sample_layers():
    layer = tg.RandomPostFX(**GRADE_RANGES, tonemap="aces", aces=True)
    images = hdr_batch(batch=4)
    assert_matches_per_sample(layer, images, layer(images, generator=seeded(6)))


def test_skipped_samples_are_tone_mapped_ungraded_and_applied_ones_graded(device):
    """The output transform applies to every sample, so a batch never mixes scene- and display-referred values."""
    layer = tg.RandomPostFX(contrast=(20.0, 40.0), tonemap="reinhard", p=0.5)
    images = hdr_batch(batch=12, device=device)
    out = layer(images, generator=seeded(3))
    applied = layer.last_params["batch_prob"]
    assert 0 < applied.sum() < 12, "the seed should skip some samples and apply others"
    assert out.max() <= 1.0
    torch.testing.assert_close(out[~applied], images[~applied] / (1.0 + images[~applied]), rtol=1e-12, atol=1e-12)
    assert_matches_per_sample(layer, images, out)


def test_skipped_samples_are_the_input_exactly_without_an_output_transform():
    layer = tg.RandomPostFX(contrast=(20.0, 40.0), saturation=20, p=0.5)
    images = hdr_batch(batch=12)
    out = layer(images, generator=seeded(3))
    applied = layer.last_params["batch_prob"]
    assert 0 < applied.sum() < 12
    assert torch.equal(out[~applied], images[~applied])


def test_srgb_input_is_decoded_graded_and_encoded():
    layer = tg.RandomPostFX(post_exposure=(-1.0, 1.5), saturation=(-30.0, 30.0), input_space="srgb")
    images = torch.rand(5, 3, 16, 16, generator=seeded(2), dtype=torch.float64)
    out = layer(images, generator=seeded(4))
    assert out.min() >= 0.0 and out.max() <= 1.0
    assert out.max() == 1.0, "positive exposure should reach the top of the display range"
    assert_matches_per_sample(layer, images, out)


def test_srgb_round_trip_with_identity_params():
    layer = tg.RandomPostFX(contrast=(-30.0, 30.0), saturation=(-30.0, 30.0), input_space="srgb")
    images = torch.rand(4, 3, 16, 16, generator=seeded(5))
    identity = {"batch_prob": torch.ones(4, dtype=torch.bool), "contrast": torch.zeros(4), "saturation": torch.zeros(4)}
    out = layer(images, params=identity)
    torch.testing.assert_close(out, images, atol=2e-6, rtol=0)


def test_samples_differ_from_each_other():
    layer = tg.RandomPostFX(post_exposure=(-1.0, 1.0), contrast=(-30.0, 30.0), hue_shift=(-60.0, 60.0))
    images = hdr_batch(batch=1).expand(6, -1, -1, -1)
    out = layer(images, generator=seeded(0))
    for i in range(6):
        for j in range(i + 1, 6):
            assert (out[i] - out[j]).abs().max() > 1e-3


def test_same_seed_same_output_other_seed_other_output():
    layer = tg.RandomPostFX(**FULL)
    images = hdr_batch()
    first = layer(images, generator=seeded(7))
    assert torch.equal(layer(images, generator=seeded(7)), first)
    assert not torch.allclose(layer(images, generator=seeded(8)), first)


def test_global_generator_is_used_without_a_generator():
    layer = tg.RandomPostFX(contrast=(-30.0, 30.0))
    images = hdr_batch()
    torch.manual_seed(11)
    first = layer(images)
    torch.manual_seed(11)
    assert torch.equal(layer(images), first)


def test_replay_on_another_tensor(device):
    layer = tg.RandomPostFX(**FULL, p=0.7)
    images, labels = hdr_batch(seed=1, device=device), hdr_batch(seed=2, device=device)
    layer(images, generator=seeded(9))
    params = layer.last_params
    replayed = layer(labels, params=params)
    assert torch.equal(replayed, layer(labels, generator=seeded(9)))
    assert layer.last_params is not None and torch.equal(layer.last_params["batch_prob"], params["batch_prob"])


def test_replay_rejects_params_of_another_layer():
    layer = tg.RandomPostFX(contrast=(-30.0, 30.0))
    images = hdr_batch(batch=4)
    with pytest.raises(ValueError, match="keys"):
        layer(images, params={"batch_prob": torch.ones(4, dtype=torch.bool)})
    with pytest.raises(ValueError, match="4 per-sample values"):
        layer(images, params={"batch_prob": torch.ones(3, dtype=torch.bool), "contrast": torch.zeros(3)})


def test_same_on_batch_draws_once():
    layer = tg.RandomPostFX(**FULL, p=0.5, same_on_batch=True)
    images = hdr_batch(batch=1).expand(5, -1, -1, -1)
    for seed in range(4):
        out = layer(images, generator=seeded(seed))
        for name, value in layer.last_params.items():
            assert (value == value[:1]).all(), name
        assert (out == out[:1]).all()


def test_p_zero_leaves_only_the_tone_mapper():
    images = hdr_batch()
    untouched = tg.RandomPostFX(**{**FULL, "tonemap": None}, p=0.0)
    assert torch.equal(untouched(images, generator=seeded(0)), images)
    assert not untouched.last_params["batch_prob"].any()
    layer = tg.RandomPostFX(**FULL, p=0.0)
    out = layer(images, generator=seeded(0))
    modes = layer.last_params["tonemap"]
    for index, mode in enumerate(modes.tolist()):
        torch.testing.assert_close(out[index], tg.ToneMap(MODES[mode])(images[index : index + 1])[0], rtol=1e-12, atol=1e-12)


def test_identity_ranges_are_off():
    layer = tg.RandomPostFX(contrast=(0.0, 0.0), split_shadows=(0.5, 0.5), bloom_intensity=(0.0, 0.0), bloom_threshold=(0.5, 1.0))
    assert layer.is_identity and layer.ranges == {}
    images = hdr_batch()
    assert layer(images) is images


def test_hdr_output_is_not_clamped_without_a_tone_mapper():
    layer = tg.RandomPostFX(post_exposure=(0.5, 1.0), saturation=(-20.0, 20.0))
    out = layer(hdr_batch(), generator=seeded(0))
    assert out.max() > 50.0


def test_single_image_and_keepdim():
    image = hdr_batch(batch=1)[0]
    assert tg.RandomPostFX(contrast=(-30.0, 30.0))(image).shape == (1, 3, 32, 32)
    assert tg.RandomPostFX(contrast=(-30.0, 30.0), keepdim=True)(image).shape == (3, 32, 32)


def test_float16_in_float16_out():
    layer = tg.RandomPostFX(**FULL)
    images = hdr_batch(dtype=torch.float32)
    out32 = layer(images, generator=seeded(1))
    out16 = layer(images.half(), generator=seeded(1))
    assert out16.dtype == torch.float16
    torch.testing.assert_close(out16.float(), out32, atol=2e-2, rtol=1e-2)


def test_gradients_are_finite_at_extremes():
    layer = tg.RandomPostFX(**FULL, p=0.5)
    images = hdr_batch(dtype=torch.float32)
    images[:, :, 0, :4] = torch.tensor([0.0, 1e-30, 65504.0, 1e30])
    images.requires_grad_(True)
    layer(images, generator=seeded(2)).square().sum().backward()
    assert torch.isfinite(images.grad).all()
    assert images.grad.abs().sum() > 0


def test_no_grad():
    layer = tg.RandomPostFX(**FULL)
    images = hdr_batch().requires_grad_(True)
    with torch.no_grad():
        out = layer(images, generator=seeded(0))
    assert not out.requires_grad and torch.isfinite(out).all()


def test_sampled_parameters_stay_inside_their_ranges():
    layer = tg.RandomPostFX(**FULL, p=0.3)
    params = layer.sample_params(10_000, generator=seeded(0))
    for name, (low, high) in {**GRADE_RANGES, **BLOOM_RANGES}.items():
        value = params[name]
        assert value.shape == ((10_000, 3) if name in ("split_shadows", "split_highlights") else (10_000,))
        assert value.min() >= low and value.max() <= high, name
        span = high - low
        assert value.min() < low + 0.01 * span and value.max() > high - 0.01 * span, f"{name} does not cover its range"
    counts = torch.bincount(params["tonemap"], minlength=len(MODES))
    assert len(counts) == len(MODES) and (counts > 2200).all()
    assert 0.27 < params["batch_prob"].float().mean() < 0.33


class SameImageDataset(torch.utils.data.Dataset):
    """One 3x8x8 HDR image eight times, augmented in the worker: outputs differ only by the draws."""

    def __init__(self, layer):
        self.layer = layer
        self.image = hdr_batch(batch=1, size=8, dtype=torch.float32)[0]

    def __len__(self):
        return 8

    def __getitem__(self, index):
        return self.layer(self.image)


@contextlib.contextmanager
def default_sigchld():
    """Give back the SIGCHLD handler that a DataLoader with workers installs for the rest of the process.

    With PyTorch's handler left in place, a later ``subprocess.run`` in the same test process was killed
    by SIGSEGV (si_code SI_KERNEL) while waiting for its child, after the suite's earlier tests.
    """
    previous = signal.getsignal(signal.SIGCHLD)
    try:
        yield
    finally:
        signal.signal(signal.SIGCHLD, previous)


def test_pickles_and_runs_in_dataloader_workers():
    layer = tg.RandomPostFX(contrast=(-40.0, 40.0), saturation=(-40.0, 40.0), tonemap=("neutral", "reinhard"), keepdim=True)
    images = hdr_batch(size=8)
    copy = pickle.loads(pickle.dumps(layer))
    assert torch.equal(copy(images, generator=seeded(1)), layer(images, generator=seeded(1)))

    dataset = SameImageDataset(layer)
    with default_sigchld():
        out = torch.cat(list(torch.utils.data.DataLoader(dataset, batch_size=4, num_workers=2)))
    assert out.shape == (8, 3, 8, 8) and torch.isfinite(out).all()
    assert out.max() <= 1.0 < dataset.image.max(), "every sample should be tone mapped"
    assert not torch.equal(out[0:4], out[4:8]), "the two workers (one batch each) should draw different parameters"


@pytest.mark.parametrize(
    "arguments, message",
    [
        (dict(contrast=(30.0, -30.0)), "contrast must be None or a"),
        (dict(contrast=(-150.0, 0.0)), r"contrast .* inside \[-100.0, 100.0\]"),
        (dict(hue_shift=-30.0), "hue_shift must be None or a"),
        (dict(saturation=(0.0, float("nan"))), "saturation"),
        (dict(split_shadows=(0.0, 1.5)), "split_shadows"),
        (dict(bloom_scatter=(0.0, 0.5), bloom_mode="scattering"), "bloom_scatter"),
        (dict(bloom_intensity=(-1.0, 1.0)), "bloom_intensity"),
        (dict(bloom_scatter=(0.2, 0.5)), "scattering mode"),
        (dict(bloom_intensity=(0.0, 1.0), bloom_mode="glow"), "bloom_mode"),
        (dict(split_balance=(-20.0, 20.0)), "split_balance changes nothing"),
        (dict(tonemap="no_such_curve"), "tonemap must be"),
        (dict(tonemap=()), "tonemap must be"),
        (dict(input_space="log"), "input_space"),
        (dict(p=1.5), "p must be a probability"),
    ],
)
def test_bad_arguments_raise_naming_the_argument(arguments, message):
    with pytest.raises(ValueError, match=message):
        tg.RandomPostFX(**arguments)


def test_bad_images_raise():
    layer = tg.RandomPostFX(contrast=(-30.0, 30.0))
    with pytest.raises(TypeError, match="floating-point"):
        layer(torch.zeros(2, 3, 4, 4, dtype=torch.uint8))
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        layer(torch.zeros(1, 2, 2, 3, 4, 4))
