"""RandomPostFX inside kornia's containers and in the shapes and habits kornia users bring: replay,
inverse, masks and boxes, scalar ranges, clips, 0..255 floats, configs and threads."""

import json
from concurrent.futures import ThreadPoolExecutor

import kornia.augmentation as K
import pytest
import torch

import torchgrade as tg


def hdr(batch=4, size=16, seed=0):
    generator = torch.Generator().manual_seed(seed)
    return torch.rand(batch, 3, size, size, generator=generator) ** 2 * 6.0


def pipeline():
    return K.AugmentationSequential(
        K.RandomHorizontalFlip(),
        tg.RandomPostFX(contrast=(-40, 40), saturation=(-40, 40), tonemap=("neutral", "reinhard"), p=0.75),
        K.RandomCrop((12, 12)),
        data_keys=["input", "mask", "bbox_xyxy"],
    )


def test_replay_through_augmentation_sequential_is_exact():
    seq = pipeline()
    images, masks = hdr(), (hdr(seed=1)[:, :1] > 3).float()
    boxes = torch.tensor([[[2.0, 2.0, 9.0, 9.0]]]).repeat(4, 1, 1)
    out, out_masks, out_boxes = seq(images, masks, boxes)
    recorded = dict(seq._params[1].data)
    assert {"batch_prob", "contrast", "saturation", "tonemap"} <= set(recorded), "kornia should record the draw"
    replayed, replayed_masks, replayed_boxes = seq(images, masks, boxes, params=seq._params)
    assert torch.equal(replayed, out) and torch.equal(replayed_masks, out_masks) and torch.equal(replayed_boxes, out_boxes)


def test_masks_and_boxes_see_only_the_geometric_layers():
    graded = K.AugmentationSequential(K.RandomHorizontalFlip(p=1.0), tg.RandomPostFX(contrast=40), data_keys=["input", "mask", "bbox_xyxy"])
    plain = K.AugmentationSequential(K.RandomHorizontalFlip(p=1.0), data_keys=["input", "mask", "bbox_xyxy"])
    images, masks = hdr(), (hdr(seed=1)[:, :1] > 3).float()
    boxes = torch.tensor([[[2.0, 3.0, 9.0, 11.0]]]).repeat(4, 1, 1)
    _, masks_graded, boxes_graded = graded(images, masks, boxes)
    _, masks_plain, boxes_plain = plain(images, masks, boxes)
    assert torch.equal(masks_graded, masks_plain) and torch.equal(boxes_graded, boxes_plain)


def test_inverse_undoes_the_flip_and_leaves_the_grade():
    seq = K.AugmentationSequential(K.RandomHorizontalFlip(p=1.0), tg.RandomPostFX(contrast=40, p=1.0), data_keys=["input"])
    images = hdr()
    out = seq(images)
    graded = tg.RandomPostFX(contrast=40)(images.flip(-1), params=seq._params[1].data).flip(-1)
    assert torch.allclose(seq.inverse(out), graded, atol=1e-6), "inverse should flip back and keep the grade (identity inverse)"


def test_params_come_second_as_in_kornias_forward():
    """kornia's ``forward(input, params=None)`` takes the draw second: ``layer(x, params)`` replays it (the generator,
    once second, took the dict and failed with ``AttributeError``)."""
    layer = tg.RandomPostFX(contrast=(-20.0, 20.0), p=1.0)
    images = hdr()
    out = layer(images, generator=torch.Generator().manual_seed(0))
    assert torch.equal(layer(images, dict(layer._params)), out)


def test_scalar_ranges_are_symmetric_about_the_identity():
    layer = tg.RandomPostFX(contrast=30, split_shadows=0.2, hue_shift=0)
    assert layer.ranges == {"contrast": (-30.0, 30.0), "split_shadows": (0.3, 0.7)}
    with pytest.raises(ValueError, match=r"contrast must be .* magnitude"):
        tg.RandomPostFX(contrast=150)


@pytest.mark.parametrize("same_on_frame", [True, False])
def test_clips_get_one_look_per_clip_or_per_frame(same_on_frame):
    layer = tg.RandomPostFX(contrast=(-40, 40), saturation=(-40, 40), same_on_frame=same_on_frame)
    frame = hdr(batch=2)
    clips = frame.unsqueeze(1).expand(2, 3, 3, 16, 16).contiguous()  # every frame of a clip the same image
    out = layer(clips, generator=torch.Generator().manual_seed(3))
    assert out.shape == clips.shape
    rows = 2 if same_on_frame else 6
    assert layer.last_params["contrast"].shape == (rows,)
    assert torch.equal(out[:, 0], out[:, 2]) == same_on_frame
    assert torch.equal(layer(clips, params=layer.last_params), out)


def test_srgb_floats_in_0_255_raise_instead_of_clamping():
    layer = tg.RandomPostFX(contrast=20, input_space="srgb")
    with pytest.raises(ValueError, match="divide 0..255 images by 255"):
        layer(torch.rand(2, 3, 4, 4) * 255)
    assert layer(torch.rand(2, 3, 4, 4)).max() <= 1.0


def test_config_round_trips_through_json():
    layer = tg.RandomPostFX(contrast=30, split_highlights=(0.4, 0.6), bloom_intensity=(0.2, 1.0), bloom_mode="scattering",
                            bloom_scatter=(0.3, 0.6), tonemap=("aces", "neutral"), p=0.5, same_on_frame=False)
    config = json.loads(json.dumps(layer.to_config()))
    copy = tg.RandomPostFX.from_config(config)
    images = hdr()
    assert copy.to_config() == config
    assert torch.equal(copy(images, generator=torch.Generator().manual_seed(5)),
                       layer(images, generator=torch.Generator().manual_seed(5)))
    with pytest.raises(ValueError, match="unknown RandomPostFX argument"):
        tg.RandomPostFX.from_config({"brightness": 0.2})


def test_threads_sharing_a_layer_each_read_back_their_own_draw():
    layer = tg.RandomPostFX(contrast=(-40, 40), saturation=(-40, 40), tonemap=("neutral", "reinhard"))
    images = hdr(batch=2, size=8)

    def draw_and_replay(seed):
        out = layer(images, generator=torch.Generator().manual_seed(seed))
        params = layer.last_params
        expected = layer.sample_params(2, torch.Generator().manual_seed(seed))
        same_draw = all(torch.equal(params[name], expected[name]) for name in expected)
        return same_draw and torch.equal(layer(images, params=params), out)

    with ThreadPoolExecutor(8) as pool:
        results = list(pool.map(draw_and_replay, range(64)))
    assert all(results), f"{results.count(False)} of 64 threads read another thread's draw"
