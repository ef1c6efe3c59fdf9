"""The GPU's execution policy (whole frames, no reads) gives the CPU policy's values: run here on the CPU by handing
every module the policy a GPU gets."""

import importlib
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import torchgrade as tg
from torchgrade.runtime import policy

ROOT = Path(__file__).resolve().parents[2]

USERS = ["torchgrade.runtime.strips", "torchgrade.runtime.policy"]
"""Every module that asks ``policy_for``."""

LOOKS = {
    "cinematic": {"exposure": {"metering": "histogram", "metering_mask": "center"},
                  "bloom": {"threshold": 1.0, "knee": 0.5, "intensity": 0.6, "scatter": 0.7, "clamp": 16.0},
                  "grade": {"aces": True, "contrast": 15, "split_shadows": [0.45, 0.5, 0.56]}, "tonemap": {"mode": "aces"}},
    "bloom-fireflies-bicubic": {"bloom": {"mode": "additive", "fade_fireflies": True, "bicubic_upsampling": True,
                                          "karis_average": True, "intensity": 1.5}},
    "bloom-anamorphic": {"bloom": {"anamorphic_ratio": 0.6, "intensity": 0.8}},
    "aces2": {"grade": {"contrast": 20, "split_highlights": [0.6, 0.5, 0.4]}, "tonemap": {"mode": "aces2"}},
}


@pytest.fixture
def gpu_policy(monkeypatch):
    """``policy_for`` answering with the whole-frames policy for every device, as it does for CUDA."""
    def whole_frames(device):
        return policy.WHOLE_FRAMES

    for name in USERS:
        monkeypatch.setattr(importlib.import_module(name), "policy_for", whole_frames)


@pytest.fixture(scope="module")
def desk():
    return tg.io.read_exr("../shared/data/exr/Desk.exr")[:3].unsqueeze(0)


@pytest.mark.parametrize("mask", ["average", "spot"])
def test_a_batch_of_histograms_meters_each_image_as_it_alone(mask, desk):
    frames = torch.cat([desk, desk.flip(-1) * 4, desk.flip(-2) * 0.01])
    metered = tg.exposure.meter_luminance(frames, "histogram", mask=mask)
    alone = torch.cat([tg.exposure.meter_luminance(frame[None], "histogram", mask=mask) for frame in frames])
    torch.testing.assert_close(metered, alone, rtol=1e-5, atol=0)


@pytest.mark.parametrize("width", [5, 8, 13])
def test_a_histogram_counts_into_its_tables_what_one_table_counts(width, monkeypatch):
    """Integer weights (each pixel's own value, rounded to 1/8) make every sum exact: any order of the additions, and so
    the split into tables, gives the same histogram, bit for bit. Widths below, at and past the table count."""
    from torchgrade.exposure import metering

    stops = (torch.randn(2, 1, 7, width, generator=torch.Generator().manual_seed(width)) * 3 * 8).round() / 8
    tabled = metering.histogram_band_average(stops, None, -8.0, 8.0, 10.0, 90.0)
    monkeypatch.setattr(metering, "HISTOGRAM_TABLES", 1)
    assert torch.equal(metering.histogram_band_average(stops, None, -8.0, 8.0, 10.0, 90.0), tabled)


@pytest.mark.parametrize("name", list(LOOKS))
def test_the_gpu_policy_gives_the_cpu_policys_values(name, desk, gpu_policy, request):
    look = tg.PostFX.from_config(LOOKS[name]).eval()
    with torch.no_grad():
        on_gpu_policy = look(desk)
        request.getfixturevalue("monkeypatch").undo()
        on_cpu_policy = look(desk)
    torch.testing.assert_close(on_gpu_policy, on_cpu_policy, rtol=1e-4, atol=1e-5)


@pytest.fixture(scope="module")
def extremes(exr_dir):
    from torchgrade.testing.extremes import extreme_inputs

    families = extreme_inputs(exr_dir)
    return {name: families[name].float() for name in ("all-half-values", "value-grid")}


@pytest.mark.parametrize("family", ["all-half-values", "value-grid"])
@pytest.mark.parametrize("name", list(__import__("torchgrade.testing.catalog", fromlist=["STAGE_KINDS"]).STAGE_KINDS))
def test_the_gpu_policy_gives_the_cpu_policys_values_at_the_extremes(name, family, extremes, gpu_policy, request):
    """Every stage kind on NaN, ±Inf, denormals, 65504, 1e30 and 3e38: whole frames keep the non-finite policy as the
    CPU's strips do, and the pictures agree within half an 8-bit code as a viewer sees them."""
    from torchgrade.testing.catalog import STAGE_KINDS

    kind, image = STAGE_KINDS[name], extremes[family]
    stage = kind.example()
    with torch.no_grad():
        on_gpu_policy = stage(image)
        request.getfixturevalue("monkeypatch").undo()
        on_cpu_policy = stage(image)
    assert torch.isfinite(on_gpu_policy).all()

    def seen(out):  # scene-referred light through the neutral tone mapper first
        return tg.color.linear_to_srgb((out if kind.display_referred else tg.functional.tonemap(out, "neutral")).clamp(0.0, 1.0)) * 255.0

    assert (seen(on_gpu_policy) - seen(on_cpu_policy)).abs().max() <= 0.5



def test_import_torchgrade_and_its_first_frame_leave_the_exporter_the_compiler_and_the_optional_packages_unloaded():
    """In fresh processes (this one has loaded them all), after ``import torch``: ONNX's exporter (``torch.onnx``, about
    0.1 s, which constants computed at import loaded by asking whether an export was running, and the first frame by
    asking again), the compiler and the optional packages load at their first use; after a training frame of the
    cinematic look (its bloom loads kornia), still neither the exporter nor the compiler. The import time's share that
    can grow unseen, counted instead of timed (``benchmarks/bench_import.py`` times it)."""
    from benchmarks.bench_import import import_once

    assert import_once(ROOT, write_bytecode=False)["loaded"] == []
    frame = ("import json, sys, torch, torchgrade as tg; "
             "look = tg.PostFX.from_config(json.loads(open('export/looks/cinematic.json').read())); "
             "image = tg.scene.demo_scene(32, 48)[None].requires_grad_(); look(image).mean().backward(); "
             "print(sorted(m for m in ('torch.onnx', 'torch._dynamo') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", frame], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == "[]", result.stdout
