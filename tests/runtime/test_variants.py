"""Every registered variant against its reference (``torchgrade.runtime.variants.FORMULAS``): edge values, float32,
float16 and bfloat16, its input left as it was, and the context that runs it."""

from __future__ import annotations

import importlib
import math

import pytest
import torch

import torchgrade  # noqa: F401  (imports every maths module, so that FORMULAS holds every formula)
from torchgrade.runtime.recording import untracked
from torchgrade.runtime.variants import CONTEXTS, FORMULAS, Variant
from torchgrade.tonemap.aces1.rrt import cubic_basis_hue_weight, smoothstep_hue_weight

EDGES = [0.0, 1e-40, 2.0**-16, 2.0**-15, 1e-3, 0.18, 0.5, 1.0, 60.0, 1000.0, 65504.0, 1e30, math.nan, math.inf, -math.inf,
         -1e-3, -0.5, -60.0, -1e30]
"""0, a denormal, ACEScc's knees, grey, 1, bright, the half-float top, beyond it, NaN, ±Inf and negatives."""
CODES = [-1.0, -0.1, 0.0, 0.05, 0.155, 0.3, 0.4135884, 0.6, 1.0, 1.4679964, 1.6, 10.0, math.nan, math.inf, -math.inf]
"""Log codes (ACEScc, ACEScct) across their ranges and past them."""
SLOPES = [0.0, 0.5, 1.0, 1.3, 2.0]
"""Contrast slopes ``1 + amount / 100`` over ``amount`` in [-100, 100]."""


def edges(dtype):
    return torch.tensor(EDGES, dtype=torch.float64).to(dtype)


def codes(dtype):
    return torch.tensor(CODES, dtype=torch.float64).to(dtype)


def finite_edges(dtype):
    """:data:`EDGES` as a stage passes them on: sanitized (``base.images.sanitize``: NaN to 0, bounded to ±65504)."""
    return edges(dtype).nan_to_num(nan=0.0).clamp(-65504.0, 65504.0)


def gammas(dtype):
    """Gamma-encoded values of a bounded frame, as split toning blends them: ``(3, 1, n)``, from 0 to 1."""
    return torch.linspace(0.0, 1.0, 33, dtype=torch.float64).to(dtype).expand(3, 1, 33).clone()


def weights(dtype):
    """Blend weights in [0, 1], ``(1, 1, n)``."""
    return torch.linspace(1.0, 0.0, 33, dtype=torch.float64).to(dtype).reshape(1, 1, 33)


def colours(dtype):
    """``(3, 1, n)``: :func:`finite_edges` in each channel against every other value in the others, greys included."""
    values = finite_edges(torch.float64)
    r, g, b = torch.meshgrid(values, values.roll(3), values.roll(7), indexing="ij")
    return torch.stack([r.flatten(), g.flatten(), b.flatten()]).unsqueeze(1).to(dtype)


def signed_as_arguments(v):
    """A magnitude that is 0 where ``v`` is (the precondition), and ``v``."""
    return v.abs().flip(0) * (v != 0), v


def light(dtype, height, width):
    """A ``(1, 3, height, width)`` frame of light: a seeded random field with a bright pixel in a corner."""
    frame = torch.rand(1, 3, height, width, generator=torch.Generator().manual_seed(height * 1000 + width), dtype=torch.float64)
    frame[..., 0, -1] = 60.0
    return frame.to(dtype)


def matrix(dtype):
    """A colour matrix with negative coefficients (sRGB to AP1's inverse direction and back)."""
    return torch.tensor([[1.7050, -0.6217, -0.0833], [-0.1302, 1.1408, -0.0106], [-0.0240, -0.1290, 1.1530]], dtype=dtype)


def hue_arguments(image):
    """``(a, b, |(a, b)|, atan2(b, a))`` of two of an image's planes, as the CAM passes them."""
    a, b = image[0], image[1] - image[2]
    return a, b, torch.hypot(a, b), torch.atan2(b, a)


def slope_grid(dtype, values):
    """``values`` against every slope: ``(image, k)`` with ``k`` a 0-d tensor, as the grade passes it."""
    return [(values(dtype), torch.tensor(k, dtype=dtype)) for k in SLOPES]


ARGUMENTS = {
    "torchgrade.color.transfer.safe_pow": lambda dtype: [(edges(dtype), e) for e in (0.5, 1.0 / 2.4, 2.4, 3)],
    "torchgrade.color.transfer.aces_to_acescc": lambda dtype: [(edges(dtype),)],
    "torchgrade.color.transfer.acescc_to_aces": lambda dtype: [(codes(dtype),)],
    "torchgrade.color.transfer.linear_to_acescct": lambda dtype: [(edges(dtype),)],
    "torchgrade.color.transfer.acescct_to_linear": lambda dtype: [(codes(dtype),)],
    "torchgrade.grading.contrast.logc_contrast": lambda dtype: slope_grid(dtype, finite_edges),
    "torchgrade.grading.contrast.acescc_contrast": lambda dtype: slope_grid(dtype, finite_edges),
    "torchgrade.grading.toning._soft_light_by_channel": lambda dtype: [
        (gammas(dtype), (weights(dtype),), offsets) for offsets in (((-0.2, 0.0, 0.3),), ((0.5, -0.5, 0.0),))],
    "torchgrade.grading.toning._toned": lambda dtype: [
        (gammas(dtype), weights(dtype), torch.tensor([-0.2, 0.0, 0.3], dtype=dtype).reshape(3, 1, 1),
         torch.tensor([0.1, -0.4, 0.0], dtype=dtype).reshape(3, 1, 1))],
    "torchgrade.tonemap.base.limited": lambda dtype: [(edges(dtype),), (edges(dtype), 60.0), (edges(dtype), 1.0)],
    "torchgrade.tonemap.aces1.fits._dim_surround_power": lambda dtype: [(finite_edges(dtype).clamp(0.0, 65504.0),)],
    "torchgrade.tonemap.aces1.fits.aces_fitted": lambda dtype: [(colours(dtype),)],
    "torchgrade.tonemap.aces1.fits.aces": lambda dtype: [(colours(dtype),), (colours(dtype), False)],
    "torchgrade.tonemap.aces1.rrt._glow": lambda dtype: [(finite_edges(dtype).clamp_min(0.0), torch.tensor(g, dtype=dtype), 0.08)
                                                       for g in (0.0, 0.025, 0.05)],
    "torchgrade.tonemap.aces1.rrt.rrt_glow_and_red_modifier": lambda dtype: [(colours(dtype).clamp_min(0.0), weight)
                                                                           for weight in (smoothstep_hue_weight, cubic_basis_hue_weight)],
    "torchgrade.tonemap.aces1.rrt._red_centered_hue": lambda dtype: [(colours(dtype).clamp_min(0.0),)],
    "torchgrade.tonemap.aces2.cam._signed_as": lambda dtype: [signed_as_arguments(finite_edges(dtype))],
    "torchgrade.tonemap.aces2.cam._safe_hypot_atan2": lambda dtype: [tuple(colours(dtype)[:2])],
    "torchgrade.tonemap.aces2.cam._hue_cos_sin": lambda dtype: [hue_arguments(colours(dtype))],
    "torchgrade.base.planes.apply_matrix": lambda dtype: [(matrix(dtype), colours(dtype)), (matrix(dtype).expand(2, 3, 3), colours(dtype).expand(2, 3, 1, -1))],
    "torchgrade.base.planes.matrix_on_planes": lambda dtype: [(matrix(dtype), colours(dtype).split(1, dim=-3))],
    "torchgrade.base.planes.channel_sum": lambda dtype: [(colours(dtype), (0.2126, 0.7152, 0.0722)), (colours(dtype).split(1, dim=-3), (1.0, -2.0, 0.5))],
    "torchgrade.base.planes.bounded_pow": lambda dtype: [(finite_edges(dtype), e) for e in (0.5, 1.0, 2.4, torch.tensor(1.7, dtype=dtype))],
    "torchgrade.bloom.pyramid.active_levels": lambda dtype: [(torch.zeros(1, 3, h, w, dtype=dtype), 16, 2)
                                                             for h, w in ((1080, 1920), (37, 53), (1, 1), (64, 9))],
    "torchgrade.bloom.pyramid.halve": lambda dtype: [(light(dtype, h, w),) for h, w in ((8, 6), (7, 6), (1, 1), (2, 2))],
    "torchgrade.bloom.pyramid.expand": lambda dtype: [(light(dtype, 3, 4), size) for size in ((6, 8), (5, 7), (6, 7))],
    "torchgrade.bloom.pyramid.upsample": lambda dtype: [(light(dtype, 3, 5), sizes, bicubic) for bicubic in (False, True)
                                                        for sizes in ([(6, 10)], [(6, 10), (12, 20)], [(5, 9), (9, 17)])],
    "torchgrade.bloom.blur.mirror_pad": lambda dtype: [(light(dtype, 5, 7), radius) for radius in (0, 2, (1, 3), 9)],
    "torchgrade.bloom.blur.mirrored": lambda dtype: [(light(dtype, 5, 7), axis, radius) for axis in (-2, -1) for radius in (0, 3, 6)],
    "torchgrade.bloom.blur.unity_blur": lambda dtype: [(light(dtype, h, w),) for h, w in ((6, 7), (1, 1), (40, 3))],
    "torchgrade.tonemap.aces2.gamut.count_below": lambda dtype: [(torch.linspace(0.0, 360.0, n, dtype=dtype), finite_edges(dtype))
                                                                 for n in (1, 2, 5, 362)],
    "torchgrade.tonemap.aces2.gamut._gathered_columns": lambda dtype: [
        (torch.arange(24, dtype=dtype).reshape(8, 3), torch.tensor([[2, 0, 1], [1, 1, 0]]))],
}
"""Each formula's arguments over its domain and past it, by dtype."""

PUBLIC_DTYPES = (torch.float32, torch.float16, torch.bfloat16)
"""What a public formula may be given (``tg.color``'s transfer functions)."""
WORKING_DTYPES = (torch.float32, torch.float64)
"""What a stage's formulas compute in (``base.images.working_dtype``: half images in float32)."""
DTYPES = {name: WORKING_DTYPES for name in ARGUMENTS
          if name.startswith(("torchgrade.grading.", "torchgrade.tonemap.", "torchgrade.base.", "torchgrade.bloom."))}
"""The dtypes each formula is reached with, :data:`PUBLIC_DTYPES` where not named here."""
EXPORTED_DTYPES = (torch.float32,)
"""What an exported graph computes in (``tg.onnx.frames``: float32 whatever its inputs and outputs)."""
ULPS = 32
"""How much further than its reference (in that dtype) a variant may land from the float64 reference, in units in the
last place of the dtype at the value, or at the output's typical size (its median, at least 1) below it: a variant
rounds differently, and a power taken as the exponential of a
logarithm (``exp(e ln x)``, ``2^(k log2 u)``) carries the logarithm's rounding, up to ``|log2 65504| = 16`` ulps of it,
into the result's relative error, twice over for the two steps."""

VARIANTS = [(name, context) for name, entry in sorted(FORMULAS.items()) for context in entry.variants]


def test_every_formula_with_variants_has_arguments_here():
    assert sorted(name for name, entry in FORMULAS.items() if entry.variants) == sorted(ARGUMENTS)


@pytest.mark.parametrize(("name", "context", "dtype"), [
    (name, context, dtype) for name, context in VARIANTS
    for dtype in (EXPORTED_DTYPES if context == "export" else DTYPES.get(name, PUBLIC_DTYPES))])
def test_every_variant_gives_its_references_values_and_leaves_its_input(name, context, dtype):
    """``|variant - truth| <= |reference - truth| + ULPS ulp(truth)``, the truth the reference in float64; NaN and
    infinities where the reference has them."""
    entry = FORMULAS[name]
    variant = entry.variants[context]
    for args in ARGUMENTS[name](dtype):
        if variant.when is not None and not variant.when(*args):
            continue
        if context == "export":  # an exported graph replaces NaN at its input (base.images.sanitize): none reaches a formula
            args = tuple(a.nan_to_num(nan=0.0, posinf=math.inf, neginf=-math.inf) if isinstance(a, torch.Tensor) else a for a in args)
        before = [a.clone() if isinstance(a, torch.Tensor) else a for a in args]
        with torch.no_grad():
            truth = entry.reference(*(as_float64(a) for a in args))
            expected = entry.reference(*before)
            got = variant.function(*args)
        if isinstance(got, tuple) and not isinstance(expected, tuple):  # a planes form's rows, as a tuple
            got = torch.stack(got)
        for part, (g, e, t) in enumerate(zip(*map(as_tuple, (got, expected, truth)), strict=True)):
            assert g.dtype == e.dtype and g.shape == e.shape
            within_ulps(g, e, t, dtype, f"{name} {context} {dtype} {args[1:]}, output {part}")
        if got is not args[0]:  # a variant may write only into the image it returns, a temporary of its caller
            for a, b in zip(args, before):
                if isinstance(a, torch.Tensor):
                    torch.testing.assert_close(a, b, equal_nan=True, rtol=0, atol=0)


def as_tuple(output) -> tuple:
    """A formula's output as a tuple of tensors (some return several)."""
    return output if isinstance(output, tuple) else (output,)


def as_float64(value):
    if isinstance(value, torch.Tensor):
        return value.double() if value.is_floating_point() else value
    if isinstance(value, tuple):
        return tuple(as_float64(v) for v in value)
    return value


def within_ulps(got, expected, truth, dtype, label):
    got, expected = got.double(), expected.double()
    finite = torch.isfinite(expected)
    assert torch.equal(torch.isnan(got), torch.isnan(expected)), label
    assert torch.equal(got[~finite & ~torch.isnan(expected)], expected[~finite & ~torch.isnan(expected)]), label
    size = truth[torch.isfinite(truth)].abs().median().clamp_min(1.0) if torch.isfinite(truth).any() else 1.0
    ulp = torch.finfo(dtype).eps * truth.abs().clamp_min(size)
    allowed = (expected - truth).abs() + ULPS * ulp
    error = (got - truth).abs()
    assert bool((error[finite] <= allowed[finite]).all()), (label, got[finite][error[finite] > allowed[finite]],
                                                             truth[finite][error[finite] > allowed[finite]])


@pytest.mark.parametrize(("name", "context"), VARIANTS)
def test_each_variant_runs_in_its_context_only(name, context, monkeypatch):
    """A variant runs where its context holds (the others made not to), and the reference where none does; an in-place
    form never where a gradient is recorded."""
    entry = FORMULAS[name]
    variant = entry.variants[context]
    args = next(a for a in ARGUMENTS[name](torch.float32) if variant.when is None or variant.when(*a))
    calls = []
    monkeypatch.setitem(entry.variants, context, Variant(context, lambda *a: calls.append(context) or entry.reference(*a), variant.when))
    module, function = name.rsplit(".", 1)
    run = getattr(importlib.import_module(module), function)
    for other in CONTEXTS:
        monkeypatch.setitem(CONTEXTS, other, lambda tensors: False)
    with torch.no_grad():
        run(*args)
    assert calls == []  # no context holds: the reference
    monkeypatch.setitem(CONTEXTS, context, lambda tensors: True)
    with torch.no_grad():
        run(*args)
    assert calls == [context]
    if context == "untracked":
        monkeypatch.setitem(CONTEXTS, context, lambda tensors: untracked(*tensors))
        tracked = [a.clone().requires_grad_() if isinstance(a, torch.Tensor) and a.is_floating_point() else a for a in args]
        assert as_tuple(run(*tracked))[0].requires_grad and calls == [context]


@pytest.mark.parametrize("dtype", WORKING_DTYPES, ids=str)
@pytest.mark.parametrize("name", [name for name, context in VARIANTS if context == "planes"])
def test_every_planes_form_has_its_references_gradients(name, dtype):
    """The planes forms run where gradients are recorded (a compiled training step): the gradient of a weighted sum of
    the output with respect to every floating-point tensor argument, against the reference's, within :data:`ULPS` of
    the largest gradient."""
    entry = FORMULAS[name]
    generator = torch.Generator().manual_seed(0)
    for args in ARGUMENTS[name](dtype):
        grads = []
        for function in (entry.reference, entry.variants["planes"].function):
            inputs = [a.clone().requires_grad_() if isinstance(a, torch.Tensor) and a.is_floating_point() else a for a in args]
            out = function(*inputs)
            out = torch.stack(out) if isinstance(out, tuple) else out
            weights = torch.rand(out.shape, generator=generator.manual_seed(1), dtype=torch.float64).to(dtype)
            tensors = [a for a in inputs if isinstance(a, torch.Tensor) and a.requires_grad]
            grads.append(torch.autograd.grad((out * weights).sum(), tensors))
        for reference, variant in zip(*grads):
            assert torch.isfinite(variant).all()
            scale = float(reference.abs().max())
            torch.testing.assert_close(variant, reference, rtol=ULPS * torch.finfo(dtype).eps, atol=ULPS * torch.finfo(dtype).eps * scale)


def test_the_contexts_hold_where_they_say_on_an_eager_cpu():
    x, tracked = torch.ones(2), torch.ones(2, requires_grad=True)
    holds = {context: bool(test([x])) for context, test in CONTEXTS.items()}
    assert holds == {"export": False, "graph": False, "untracked": True, "planes": False, "kernels": False, "host": True,
                     "sizes": True}
    assert not CONTEXTS["untracked"]([tracked]) and not CONTEXTS["host"]([torch.ones(2, device="meta")])
    assert CONTEXTS["kernels"]([torch.ones(2, device="meta")])  # a device whose every read waits: a GPU's policy
