"""RandomPostFX as a compiler is given it, run eagerly: its grade on the image's planes and the output finished plane by
plane (:func:`~torchgrade.runtime.strips.pixelwise`), against its eager form on the same draw, in outputs and
gradients, on ordinary and extreme values. (That Inductor then writes only the output: ``tests/runtime/test_gpu_path.py``.)"""

import pytest
import torch

import torchgrade as tg

from reference.compiled import as_compiled, outputs_and_gradients
from test_augment import FULL, GRADE_RANGES, hdr_batch, seeded

LAYERS = {
    "jiggle-srgb": dict(contrast=30, saturation=30, hue_shift=20, post_exposure=0.5, input_space="srgb", p=0.5),
    "full": dict(FULL, p=0.5),
    "aces": dict(GRADE_RANGES, tonemap="aces", aces=True, p=0.5),
}


def _images(name: str) -> torch.Tensor:
    """A batch of 8 with the extremes in its first row: display values for an sRGB layer, scene values otherwise."""
    if name.endswith("srgb"):
        images = torch.rand(8, 3, 16, 16, generator=seeded(2), dtype=torch.float64)
        images[:, :, 0, :4] = torch.tensor([0.0, 1e-30, 1.0, 0.5], dtype=torch.float64)
        return images
    images = hdr_batch(batch=8, size=16)
    images[:, :, 0, :6] = torch.tensor([0.0, 1e-30, 0.18, 60.0, 65504.0, 1e30], dtype=torch.float64)
    return images


@pytest.mark.parametrize("name", sorted(LAYERS))
def test_as_compiled_equals_eager_on_the_same_draw(monkeypatch, name):
    layer, images = tg.RandomPostFX(**LAYERS[name]), _images(name)
    layer(images, generator=seeded(3))
    params = layer.last_params
    assert 0 < params["batch_prob"].sum() < 8, "the seed should skip some samples and apply others"
    replayed = lambda x: layer(x, params=params)  # noqa: E731
    eager = outputs_and_gradients(replayed, images)
    as_compiled(monkeypatch)
    compiled = outputs_and_gradients(replayed, images)
    for ours in compiled:
        assert torch.isfinite(ours).all()
    torch.testing.assert_close(compiled[0], eager[0], rtol=1e-9, atol=1e-9)
    # A grey pixel is where HSV's maximum ties three ways: the hue shift is differentiable there only along the grey
    # axis, and eager (amax: a third each) and the planes (two maximums: a quarter, a quarter, a half) take different
    # subgradients. Along that axis, the sum over the channels, they agree; elsewhere, everywhere.
    grey = (images == images[:, :1]).all(dim=1, keepdim=True).expand_as(images)
    assert grey.any()
    torch.testing.assert_close(compiled[1][~grey], eager[1][~grey], rtol=1e-9, atol=1e-9)
    torch.testing.assert_close(compiled[1].sum(dim=1), eager[1].sum(dim=1), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_as_compiled_equals_eager_in_low_precision(monkeypatch, dtype):
    """Linear input, the finish casting each plane back to the input's dtype: eager's values to one step of the dtype."""
    layer = tg.RandomPostFX(contrast=30, saturation=30, hue_shift=20, post_exposure=0.5, p=0.5)
    images = _images("jiggle").to(dtype)
    eager = layer(images, generator=seeded(3))
    params = layer.last_params
    as_compiled(monkeypatch)
    compiled = layer(images, params=params)
    assert compiled.dtype == dtype
    # a skipped sample is its input exactly, 1e30 cast to float16 (inf) included: equal there, as assert_close takes inf
    step = torch.finfo(dtype).eps
    torch.testing.assert_close(compiled.float(), eager.float(), rtol=step, atol=step)


def test_as_compiled_equals_eager_on_clips(monkeypatch):
    """Clips ``(B, T, 3, H, W)``, one draw a clip: the frames come back in the clip's shape, as eager's."""
    layer = tg.RandomPostFX(**LAYERS["jiggle-srgb"])
    clips = _images("jiggle-srgb").reshape(4, 2, 3, 16, 16)
    eager = layer(clips, generator=seeded(5))
    params = layer.last_params
    as_compiled(monkeypatch)
    compiled = layer(clips, params=params)
    assert compiled.shape == clips.shape
    torch.testing.assert_close(compiled, eager, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", sorted(LAYERS))
def test_a_compiled_layer_takes_a_generator_as_an_eager_one_does(monkeypatch, name):
    """``tg.compile(layer)(x, generator=g)``: the draw is made before the graph (Dynamo cannot take a generator into
    one), the same draw as eager's from the same seed, and the same batch; a 5-D clip draws once a clip. Dynamo's
    capture alone (backend "eager", ``fullgraph=True``): the capture is what refused the generator."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda *args, options=None, **kwargs: real(*args, **{**kwargs, "backend": "eager"}))
    torch.compiler.reset()
    layer, images = tg.RandomPostFX(**LAYERS[name]), _images(name).float()
    compiled = tg.compile(layer)
    with torch.no_grad():
        out = compiled(images, generator=seeded(5))
        drawn = layer.last_params
        expected = layer(images, generator=seeded(5))
    for key, value in layer.last_params.items():
        torch.testing.assert_close(drawn[key], value, rtol=0, atol=0)
    torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-5)
    clip = images[:6].reshape(2, 3, *images.shape[1:])
    with torch.no_grad():
        torch.testing.assert_close(compiled(clip, generator=seeded(6)), layer(clip, generator=seeded(6)), rtol=1e-5, atol=1e-5)
