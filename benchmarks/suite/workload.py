"""The suite's workload: the look, the scenes it is measured on, and the float64 reference every row is compared with.

Part of ``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]`` (see its docstring for the whole method).
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import torch
from torch import nn

import torchgrade as tg
from benchmarks import metrics
from benchmarks.common import ROOT, sample_exr

LOOK = {
    "bloom": {"mode": "scattering", "threshold": 1.0, "knee": 0.5, "intensity": 0.6, "scatter": 0.7},
    "grade": {"aces": True, "post_exposure": 0.5, "temperature": 20, "contrast": 30, "saturation": 20,
              "split_shadows": [0.42, 0.5, 0.6], "split_highlights": [0.6, 0.5, 0.42]},
    "tonemap": {"mode": "aces"},
}
EXR_NAMES = ("Desk", "CandleGlass", "GoldenGate", "BrightRings")
DEMO_SIZE = (720, 1280)
FRAME = (1080, 1920)
RESOLUTIONS = ((256, 256), (512, 512), (1024, 1024), (1080, 1920), (2160, 3840))
BATCHES = (1, 2, 4, 8)
BATCH_SIDE = 512
QUICK_RUNS = 7
"""Rounds timed under ``--quick``: enough for every ratio of two runs to agree within 20 % on a shared
2-core machine (benchmarks/results/stability.md)."""


@dataclass(frozen=True)
class Plan:
    """What one run measures and how hard."""

    quick: bool
    device: torch.device
    out: Path
    runs: int
    scaling_runs: int
    accuracy_side: Optional[int]
    delta_e_samples: int
    resolutions: tuple
    compile: bool
    lut_sizes: tuple = (9, 17, 33, 65)
    shapers: tuple = ("linear", "logc", "logc_hdr")
    opencolorio_sizes: tuple = (9, 17, 33, 65)
    onnx_lut_interpolations: tuple = ("trilinear", "tetrahedral")
    peak_memory: bool = True

    @classmethod
    def from_args(cls, args) -> "Plan":
        """The full plan, or with ``--quick``: the LUT rows a choice hangs on (33³ and 65³, LogC and the default
        lattice; OpenColorIO at 33³; onnxruntime tetrahedral only), smaller accuracy images, scaling up to 1024²,
        no ``torch.compile``, no peak memory."""
        device, out = torch.device(args.device), Path(args.out)
        if not args.quick:
            return cls(quick=False, device=device, out=out, runs=11, scaling_runs=5, accuracy_side=None,
                       delta_e_samples=200_000, resolutions=RESOLUTIONS, compile=True)
        return cls(quick=True, device=device, out=out, runs=QUICK_RUNS, scaling_runs=3, accuracy_side=400,
                   delta_e_samples=20_000, resolutions=RESOLUTIONS[:3], compile=False, lut_sizes=(33, 65),
                   shapers=("logc", "logc_hdr"), opencolorio_sizes=(33,), onnx_lut_interpolations=("tetrahedral",),
                   peak_memory=False)

    def command(self) -> str:
        out = self.out.resolve()
        shown = out.relative_to(ROOT) if out.is_relative_to(ROOT) else out
        return f".venv/bin/python -m benchmarks suite{' --quick' if self.quick else ''} --device {self.device.type} --out {shown}"


def downscale(image: torch.Tensor, max_side: Optional[int]) -> torch.Tensor:
    """Area-average ``image`` by the smallest integer factor that brings its longer side to ``max_side``."""
    factor = 1 if max_side is None else -(-max(image.shape[-2:]) // max_side)
    return image if factor == 1 else nn.functional.avg_pool2d(image, factor, ceil_mode=True)


def accuracy_scenes(plan: Plan) -> dict:
    """The images accuracy is measured on: the sample EXRs (RGB, Rec.709) and the demo scene, ``(1, 3, H, W)``."""
    scenes = {name: sample_exr(name, to_rec709=True) for name in EXR_NAMES}
    scenes["demo scene"] = tg.scene.demo_scene(*DEMO_SIZE)
    return {name: downscale(image, plan.accuracy_side).to(plan.device) for name, image in scenes.items()}


def as_strip(images) -> torch.Tensor:
    """Images ``(1, 3, H, W)`` as one ``(1, 3, 1, P)`` row of pixels, for per-pixel stages (one call, one shape)."""
    return torch.cat([image.reshape(1, 3, 1, -1) for image in images], dim=-1)


class Workload:
    """The look, its inputs and the float64 reference, shared by every row."""

    def __init__(self, plan: Plan, folder: Path):
        self.plan = plan
        self.folder = folder
        self.look = tg.PostFX.from_config(LOOK).to(plan.device).eval()
        self.per_pixel = nn.Sequential(self.look.grade, self.look.tonemap)
        self.scenes = accuracy_scenes(plan)
        self.frame = tg.scene.demo_scene(*FRAME).to(plan.device)
        with torch.no_grad():
            reference = as_strip(self.look(scene.double()) for scene in self.scenes.values())
        self.reference_codes = metrics.srgb_codes(reference)
        pixels = self.reference_codes[0, 0].numel()
        self.delta_e_pixels = metrics.sample_indices(pixels, plan.delta_e_samples)

    @functools.lru_cache(maxsize=None)
    def bloomed_strip(self, dtype: torch.dtype) -> torch.Tensor:
        """The accuracy scenes after bloom computed on ``dtype`` input, as one strip in ``dtype``."""
        with torch.no_grad():
            return as_strip(self.look.bloom(scene.to(dtype)) for scene in self.scenes.values())

    @functools.lru_cache(maxsize=None)
    def bloomed_frame(self, dtype: torch.dtype) -> torch.Tensor:
        with torch.no_grad():
            return self.look.bloom(self.frame.to(dtype))

    @functools.lru_cache(maxsize=None)
    def lut(self, size: int, shaper: str, fitted: bool = False) -> tg.LUT3D:
        """The per-pixel stage baked (in float64) into a ``size``³ LUT, table stored in float32.

        ``fitted``: the lattice reaches the brightest bloomed pixel of the accuracy scenes
        (``bake_lut(scene=...)``) instead of the shaper's default top (LogC 1.0, linear ≈ 58.9).
        """
        scene = self.bloomed_strip(torch.float32).cpu() if fitted else None
        baked = tg.bake_lut(self.per_pixel, size=size, shaper=shaper, scene=scene)
        return float32_lut(baked).to(self.plan.device)


def float32_lut(lut: tg.LUT3D, compile: bool = False) -> tg.LUT3D:
    """A copy of ``lut`` with its table in float32 (as served), optionally looked up through ``torch.compile``."""
    served = copy.deepcopy(lut)
    served.table = lut.table.detach().float()
    served.compile = compile
    return served
