"""Devices: every public module computes on its input's device, in its input's precision, and moves whole.

Three checks, over one catalogue of cases built from the library's registries (every tone mapper,
bloom composite, LUT interpolation, export backend and shaper, display encoding, primary style,
metering and operator), so a module or mode added there is checked here without a new line:

* **Wrong-device audit** (any machine): module and image are moved to PyTorch's ``meta`` device, which
  has shapes but no data, and the forward and backward pass run under :class:`DeviceCheck`. A tensor
  created without ``device=`` (``torch.tensor``, ``torch.arange``, a constant matrix) or a table kept
  as a plain attribute stays on the CPU, and the first operation that meets it with the image raises,
  as it would on CUDA. ``meta`` alone lets ``einsum`` and ``matmul`` mix devices; the check does not.
  No case reads a value back off the CPU (which ``meta`` could not answer): ``tests/runtime/test_gpu_path.py``
  holds every case to that, after its first frame.
* **Precision**: moved with ``.to(torch.float64)`` on a float64 image, every floating tensor an operation
  reads or writes is float64 (no constant rounded through float32).
* **CPU against CUDA** (needs CUDA): the same module and batch on both give outputs within :data:`CODES` 8-bit
  codes of each other as a viewer sees them, and image gradients within :data:`GRADIENT_TOLERANCE` of their scale.

Run the whole suite on a GPU with ``TG_TEST_DEVICE=cuda`` (see ``tests/conftest.py``).
"""

from __future__ import annotations

import kornia  # noqa: F401  imported before any audit: importing it makes tensors, which the audits would see
import pytest
import torch
from torch import nn
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_leaves

import torchgrade as tg
from torchgrade.bloom.composite import BLOOM_MODES
from torchgrade.output.display import DISPLAY_ENCODINGS
from torchgrade.exposure import METERING_MODES, OPERATORS
from torchgrade.lut import INTERPOLATIONS, LUT_BACKENDS, identity_table
from torchgrade.lut.shapers import SHAPERS
from torchgrade.match import ResidualLUT
from torchgrade.match.fit import MatchedControls
from torchgrade.grading.primary import STYLES
from torchgrade.base.stage import Stage
from torchgrade.tonemap import TONE_MAPPERS

CODES = 0.5
"""CUDA's float32 kernels round differently from the CPU's (fused multiply-adds, other reduction orders in the bloom
pyramid, another libm for pow/exp/log). Outputs are compared as a viewer sees them, in 8-bit sRGB codes (below):
at most half a code apart. A scene-referred value of 117 is 3.9e-4 apart after the ACES grade (3.3e-6 relative),
invisible, yet beyond any fixed absolute tolerance small enough for values near 0 (H200, 2026-11-26)."""

GRADIENT_TOLERANCE = 1e-4
"""Image gradients agree within this fraction of the largest gradient's magnitude (the postfx case: 2.3e-3 on a
gradient of -250 on the H200). TF32 is switched off for the comparison: it is the caller's choice."""

DISPLAY_SIGNALS = ("display-",)
"""Cases whose output is an encoded display signal in [0, 1]: compared as codes of that signal."""

DISPLAY_LINEAR = ("tonemap-", "postfx", "random-postfx", "lut-", "look-lut", "dither", "match-")
"""Cases whose output is display-linear light: compared after the sRGB encoding. Every other case is scene-referred
and is viewed through the neutral tone mapper first."""


def seen_codes(out: torch.Tensor, name: str) -> torch.Tensor:
    """Case ``name``'s output as a viewer sees it, in 8-bit codes (float)."""
    if name.startswith(DISPLAY_SIGNALS):
        return out.clamp(0.0, 1.0) * 255.0
    if not name.startswith(DISPLAY_LINEAR):
        out = tg.functional.tonemap(out, "neutral")
    return tg.color.linear_to_srgb(out.clamp(0.0, 1.0)) * 255.0


GRADE = dict(post_exposure=0.5, temperature=20, tint=-10, contrast=30, color_filter=(1.0, 0.9, 0.8), split_shadows=(0.3, 0.4, 0.7),
             split_highlights=(0.8, 0.6, 0.4), split_balance=15, channel_mixer=((1.1, -0.1, 0.0), (0.05, 0.9, 0.05), (0.0, 0.2, 0.8)),
             shadows=(0.9, 0.95, 1.1), midtones=(1.05, 1.0, 0.95), highlights=(1.1, 1.0, 0.9), hue_shift=25, saturation=30)
PRIMARY = {"linear": dict(offset=(0.01, 0.0, -0.01), exposure=(0.3, 0.2, 0.1), contrast=(1.2, 1.1, 1.0), saturation=1.2),
           "log": dict(brightness=(0.05, 0.0, -0.05), contrast=(1.3, 1.2, 1.1), gamma=(0.8, 0.9, 1.0), saturation=1.1)}
assert set(PRIMARY) == set(STYLES), "a primary style without controls here"


PLAIN_NUMBERS = {("aces2_hdr", "peak_luminance")}
"""Tone mapper controls that take a number only (tables are built per value)."""


def _per_sample_controls(mode: str) -> dict:
    """Every number control of tone mapper ``mode`` as a (2,) tensor: its default and a value towards its low end."""
    controls = TONE_MAPPERS[mode].controls
    return {name: torch.tensor([c.default, 0.9 * c.default + 0.1 * c.range[0]]) for name, c in controls.items()
            if c.kind == "number" and (mode, name) not in PLAIN_NUMBERS}


class _Adapting(nn.Module):
    """Two frames of a video through :class:`~torchgrade.AutoExposure`: the second adapts from the first's state."""

    def __init__(self, exposure: tg.AutoExposure):
        super().__init__()
        self.exposure = exposure

    def forward(self, image):
        self.exposure(image * 4.0, dt=1.0 / 30.0)
        return self.exposure(image, dt=1.0 / 30.0)


class _Seeded(nn.Module):
    """A random layer drawing from a CPU generator seeded afresh: the same draws, and looks, on every device."""

    def __init__(self, layer: nn.Module):
        super().__init__()
        self.layer = layer

    def forward(self, image):
        return self.layer(image, generator=torch.Generator().manual_seed(0))


def _lut(shaper: str = "linear") -> tg.LUT3D:
    curve = torch.linspace(0.0, 1.0, 17).unsqueeze(1).expand(17, 3) ** 0.5 if SHAPERS[shaper].takes_curve else None
    return tg.LUT3D(identity_table(9) ** 1.5, shaper=shaper, curve=curve)


def _cases() -> dict:
    """Every case by name: a factory of a module whose ``forward(image)`` runs it."""
    cases = {f"tonemap-{mode}": lambda mode=mode: tg.ToneMap(mode) for mode in tg.TONEMAP_MODES}
    cases.update({f"tonemap-{mode}-per-sample": lambda mode=mode: tg.ToneMap(mode, **_per_sample_controls(mode))
                  for mode in tg.TONEMAP_MODES if _per_sample_controls(mode)})
    cases.update({f"bloom-{mode}": lambda mode=mode: tg.Bloom(mode=mode, threshold=0.8, intensity=0.5, tint=(1.0, 0.9, 0.8))
                  for mode in BLOOM_MODES})
    cases.update({f"lut-{shaper}": lambda shaper=shaper: _lut(shaper) for shaper in SHAPERS})
    # the "gather" backend is the eager lookup itself: LUT3D(...)(image, interpolation)
    cases.update({f"lut-{interpolation}-{backend}": lambda i=interpolation, b=backend: _lut().export_form(i, b)
                  for interpolation in INTERPOLATIONS for backend in LUT_BACKENDS})
    cases.update({f"display-{encoding}": lambda e=encoding: tg.Display(e, "rec2020", peak_luminance=1000.0) for encoding in DISPLAY_ENCODINGS})
    cases.update({f"primary-{style}": lambda s=style: tg.PrimaryGrade(s, **PRIMARY[s]) for style in STYLES})
    cases.update({f"exposure-{metering}-{operator}": lambda m=metering, o=operator: tg.AutoExposure(metering=m, operator=o)
                  for metering in METERING_MODES for operator in OPERATORS})
    cases.update({
        "grade": lambda: tg.ColorGrade(**GRADE),
        "grade-aces": lambda: tg.ColorGrade(aces=True, **GRADE),
        "grade-learnable": lambda: tg.ColorGrade(contrast=nn.Parameter(torch.tensor(20.0)), saturation=10),
        "grade-curves": lambda: tg.ColorGrade(
            hue_vs_hue=((0.0, 0.5), (0.3, 0.6), (0.7, 0.45)), hue_vs_sat=((0.1, 0.55), (0.6, 0.4)), sat_vs_sat=((0.0, 0.5), (1.0, 0.6)),
            lum_vs_sat=((0.0, 0.45), (0.5, 0.55), (1.0, 0.5)), curve_master=((0.0, 0.0), (0.5, 0.6), (1.0, 1.0)),
            curve_red=((0.0, 0.05), (1.0, 0.95)), curve_blue=torch.tensor([[0.0, 0.0], [0.6, 0.55], [1.0, 1.0]])),
        "grade-per-sample": lambda: tg.ColorGrade(contrast=torch.tensor([10.0, 30.0]), color_filter=torch.tensor([[1.0, 0.9, 0.8], [0.8, 0.9, 1.0]]),
                                                  channel_mixer=torch.eye(3).expand(2, 3, 3) * 0.9, aces=True),
        "bloom-per-sample": lambda: tg.Bloom(intensity=torch.tensor([0.3, 0.6]), tint=torch.tensor([[1.0, 0.9, 0.8], [0.8, 0.9, 1.0]]),
                                             dirt=torch.rand(3, 8, 8), dirt_intensity=0.5, karis_average=True),
        "bloom-anamorphic": lambda: tg.Bloom(intensity=0.5, anamorphic_ratio=0.3),
        "exposure-adapting": lambda: _Adapting(tg.AutoExposure(middle_grey=torch.tensor([0.18, 0.12]), speed_to_light=2.0, speed_to_dark=1.0)),
        "exposure-histogram-limited": lambda: _Adapting(tg.AutoExposure(
            metering="histogram", metering_mask="spot", min_ev=torch.tensor([-3.0, -1.0]), max_ev=3.0, compensation=torch.tensor([0.5, -0.5]),
            low_percent=torch.tensor([40.0, 10.0]), compensation_curve=((-8.0, -3.0), (-1.0, 0.0)))),
        "exposure-user-mask": lambda: tg.AutoExposure(metering="mean", metering_mask=torch.rand(5, 9) + 0.1, fixed_exposure=None),
        "exposure-fixed": lambda: tg.AutoExposure(fixed_exposure=torch.tensor([1.5, -0.5]), compensation=0.25),
        "lut-learnable": lambda: tg.LUT3D(identity_table(9), learnable=True),
        "bloom-export": lambda: tg.Bloom(threshold=0.8, intensity=0.5).export_form(),
        "convolution-bloom": lambda: tg.ConvolutionBloom(torch.rand(3, 7, 7), threshold=0.8, intensity=0.5),
        "convolution-bloom-export": lambda: tg.ConvolutionBloom(torch.rand(3, 7, 7), intensity=0.5).export_form(),
        "convolution-bloom-learnable": lambda: tg.ConvolutionBloom(nn.Parameter(torch.rand(3, 7, 7)), intensity=0.5),
        "dither": lambda: tg.Dither(amplitude=2.0 / 255.0),
        "look-lut": lambda: tg.LookLUT(identity_table(9) ** 1.5, contribution=torch.tensor([0.3, 0.9])),
        "postfx": lambda: tg.PostFX(exposure={}, bloom={"mode": "scattering", "intensity": 0.5}, grade={"aces": True, **GRADE},
                                    primary={"style": "log", **PRIMARY["log"]}, tonemap="aces", dither={}, display={"encoding": "srgb"}),
        "postfx-look-lut": lambda: tg.PostFX(grade=GRADE, tonemap="neutral", look_lut=tg.LookLUT(identity_table(9) ** 0.8, contribution=0.6)),
        "random-postfx": lambda: _Seeded(tg.RandomPostFX(contrast=30, saturation=20, split_shadows=0.2, bloom_intensity=(0.2, 0.6), tonemap="aces")),
        "random-postfx-tonemaps": lambda: _Seeded(tg.RandomPostFX(contrast=30, tonemap=("aces", "neutral", "agx"))),
        "match-controls": lambda: MatchedControls(("post_exposure", "contrast", "color_filter", "lift"), "filmic"),
        "match-residual": lambda: ResidualLUT(9, torch.float32),
    })
    return cases


CASES = _cases()

NOT_FLOAT64 = {name: "draws its controls as float32 uniforms (kornia's convention); the grade they drive runs in float64"
               for name in ("random-postfx", "random-postfx-tonemaps")}


def test_every_public_module_has_a_case():
    named = (getattr(tg, name) for name in tg.__all__)
    public = {obj for obj in named if isinstance(obj, type) and issubclass(obj, nn.Module)}
    covered = {type(module) for make in CASES.values() for module in make().modules()}
    assert public - covered == set()
    assert {cls for cls in public if issubclass(cls, Stage)} and tg.RandomPostFX in public


class DeviceCheck(TorchDispatchMode):
    """Raise at the first operation whose tensors lie on two devices and, with ``dtype``, at the first floating tensor
    of another dtype. A 0-d CPU tensor may join a device's tensors in an operation of two operands, where CUDA's
    kernels take it as an argument; elsewhere CUDA refuses it (``addcmul``'s first operands) or copies it to the device
    at every call (``torch.where``), and both raise here."""

    TRANSFERS = (torch.ops.aten._to_copy.default, torch.ops.aten.copy_.default)

    def __init__(self, dtype: torch.dtype | None = None):
        super().__init__()
        self.dtype = dtype

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        tensors = [t for t in tree_leaves((args, kwargs)) if isinstance(t, torch.Tensor)]
        operands = [t for t in tree_leaves((args, {k: v for k, v in kwargs.items() if k != "out"})) if isinstance(t, torch.Tensor)]
        scalars_join = len(operands) <= 2
        devices = {str(t.device) for t in tensors if t.dim() > 0 or t.device.type != "cpu" or not scalars_join}
        if len(devices) > 1 and func not in self.TRANSFERS:
            raise AssertionError(f"{func} mixes devices {sorted(devices)}")
        if self.dtype is not None:
            for t in tensors + [t for t in tree_leaves(out) if isinstance(t, torch.Tensor)]:
                if t.is_floating_point() and t.dtype != self.dtype:
                    raise AssertionError(f"{func} meets a {t.dtype} tensor of shape {tuple(t.shape)} in a {self.dtype} run")
        return out


def _audit(name: str, dtype: torch.dtype) -> None:
    """The forward and backward of a case, and its forward without autograd."""
    module = CASES[name]().to("meta", dtype)
    image = torch.empty(2, 3, 40, 56, device="meta", dtype=dtype, requires_grad=True)
    with DeviceCheck(dtype if dtype == torch.float64 else None):
        out = module(image)
        out.sum().backward()
        with torch.no_grad():
            inferred = module(image)
    assert (out.device.type, out.dtype, image.grad.device.type) == ("meta", dtype, "meta")
    assert (inferred.device.type, inferred.dtype) == ("meta", dtype)


@pytest.mark.parametrize("name", list(CASES))
def test_nothing_is_created_on_a_fixed_device(name):
    _audit(name, torch.float32)


@pytest.mark.parametrize("name", [name for name in CASES if name not in NOT_FLOAT64])
def test_a_module_moved_to_float64_computes_in_float64(name):
    _audit(name, torch.float64)


def _held_tensors(module: nn.Module):
    """Every tensor a module and its children hold: parameters, buffers and plain attributes (caches, states)."""
    for child in module.modules():
        yield from (t for t in tree_leaves(list(vars(child).values())) if isinstance(t, torch.Tensor))


@pytest.mark.parametrize("name", list(CASES))
def test_moving_a_module_moves_every_table_it_holds(name):
    module = CASES[name]()
    module(torch.rand(2, 3, 16, 16) * 4)  # fills caches and states on the CPU
    module.to("meta", torch.float64)
    module(torch.empty(2, 3, 16, 16, device="meta", dtype=torch.float64))
    for stage in (m for m in module.modules() if isinstance(m, Stage)):  # a control set after the move
        for control, value in stage.params().items():
            if not isinstance(value, torch.Tensor):
                setattr(stage, control, value)
    assert all(t.device.type == "meta" for t in _held_tensors(module))
    if name not in NOT_FLOAT64:
        assert all(t.dtype == torch.float64 for t in _held_tensors(module) if t.is_floating_point())


def test_the_audit_catches_a_constant_left_on_the_cpu():
    class Tinted(nn.Module):
        def forward(self, image):
            return torch.einsum("ij,bjhw->bihw", torch.eye(3), image)  # meta alone lets this einsum through

    with pytest.raises(AssertionError, match="mixes devices"), DeviceCheck():
        Tinted()(torch.empty(1, 3, 2, 2, device="meta"))


@pytest.fixture(scope="module")
def hdr_batch(exr_dir) -> torch.Tensor:
    """Crops of Desk (a lamp over dark wood) and CandleGlass (a flame), as a (2, 3, 40, 56) float32 batch."""
    crops = [tg.io.read_exr(exr_dir / name)[:3, y:y + 40, x:x + 56] for name, y, x in (("Desk.exr", 100, 150), ("CandleGlass.exr", 300, 200))]
    return torch.stack(crops).contiguous()


def _run(name: str, image: torch.Tensor) -> tuple:
    """Case ``name`` built afresh on ``image``'s device and run on it: its output and the image's gradient."""
    torch.manual_seed(0)  # the same textures, kernels and draws on every device
    module = CASES[name]().to(image.device)
    image = image.clone().requires_grad_()
    out = module(image)
    out.sum().backward()
    return out.detach(), image.grad


@pytest.mark.skipif(not torch.cuda.is_available(), reason="device-conditional: needs CUDA to compare with the CPU")
@pytest.mark.parametrize("name", CASES)
def test_cuda_agrees_with_the_cpu(name, hdr_batch, monkeypatch):
    monkeypatch.setattr(torch.backends.cuda.matmul, "allow_tf32", False)
    monkeypatch.setattr(torch.backends.cudnn, "allow_tf32", False)
    (out_cpu, grad_cpu), (out_cuda, grad_cuda) = _run(name, hdr_batch), _run(name, hdr_batch.cuda())
    assert out_cuda.device.type == grad_cuda.device.type == "cuda"
    codes = (seen_codes(out_cuda.cpu(), name) - seen_codes(out_cpu, name)).abs().max().item()
    assert codes <= CODES, f"{codes:.3f} 8-bit codes apart"
    scale = grad_cpu.abs().max().item()
    torch.testing.assert_close(grad_cuda.cpu(), grad_cpu, rtol=0.0, atol=GRADIENT_TOLERANCE * scale)


@pytest.mark.parametrize("evaluate", [lambda look, tmp: tg.bake_lut(look, size=5),
                                      lambda look, tmp: look.to_lut(size=5),
                                      lambda look, tmp: tg.onnx.export(look, tmp / "look.onnx")],
                         ids=["bake_lut", "to_lut", "onnx.export"])
def test_baking_and_export_of_a_look_off_the_cpu_raise_naming_the_device(tmp_path, evaluate):
    """Baking and export evaluate on the CPU; a look whose tensors are elsewhere (here on ``meta``) is
    refused before any work (a look of plain-number controls holds no tensor and goes anywhere)."""
    grade = tg.ColorGrade(contrast=nn.Parameter(torch.tensor(20.0)), lift=torch.tensor([1.0, 1.0, 0.9, 0.02]))
    look = tg.PostFX(grade=grade, tonemap="aces").to("meta")
    with pytest.raises(ValueError, match=r"on the CPU, but the look holds tensors on meta: pass look\.cpu\(\)"):
        evaluate(look, tmp_path)
    assert not (tmp_path / "look.onnx").exists()
