"""The suite's workload: the look, the photographs it is measured on, and the float64 reference every row is compared with.

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

__all__ = ["LOOK", "EXR_NAMES", "Plan", "Workload", "accuracy_scenes", "as_strip", "downscale", "float32_lut", "grid_shapers"]

LOOK = {
    "exposure": {"metering": "log", "middle_grey": 0.18},
    "bloom": {"mode": "scattering", "threshold": 1.0, "knee": 0.5, "intensity": 0.6, "scatter": 0.7},
    "grade": {"aces": True, "post_exposure": 0.5, "temperature": 20, "contrast": 30, "saturation": 20,
              "split_shadows": [0.42, 0.5, 0.6], "split_highlights": [0.6, 0.5, 0.42]},
    "tonemap": {"mode": "aces"},
}
"""One strong look: eye adaptation (each frame a first frame) and bloom run live; grade and tone map are the
per-pixel stage the rows compute in different ways."""
EXR_NAMES = ("Desk", "CandleGlass", "GoldenGate", "Carrots", "Garden", "BrightRings")
"""The sample photographs (and one synthetic HDR test image) accuracy is measured on, beside the demo scene."""
DEMO_SIZE = (720, 1280)
FRAME = (1080, 1920)
RESOLUTIONS = ((256, 256), (512, 512), (1024, 1024), (1080, 1920), (2160, 3840))
BATCHES = (1, 2, 4, 8)
BATCH_SIDE = 512
QUICK_RUNS = 7
"""Rounds timed under ``--quick``: enough for every ratio of two runs to agree within 20 % on a shared
2-core machine (benchmarks/results/stability.md)."""
QUICK_SIDE = 160
"""The longer side (pixels) the photographs are area-downscaled to under ``--quick``: small enough that the quick
form's accuracy is re-derived by the test suite (``tests/project/test_suite_results.py``) in seconds."""
GRID_SIZES = (9, 17, 33, 65)
"""LUT sizes of the full run's grid of sizes × lattices × interpolations."""


def grid_shapers() -> tuple:
    """Every lattice ``bake_lut`` bakes with a fixed shape (its default domains; not ``"fitted"``, which is fitted)."""
    return tuple(name for name in tg.lut.DEFAULT_DOMAINS if name != "fitted")


@dataclass(frozen=True)
class Plan:
    """What one run measures and how hard. ``every_row``: beside the rows a choice hangs on, the float64 reference
    timed, every LUT size × lattice × interpolation, OpenColorIO at each, lattices fitted to the scenes, the exported
    per-pixel stage and baked look, and OpenVINO's default precision."""

    quick: bool
    device: torch.device
    out: Path
    runs: int
    scaling_runs: int
    accuracy_side: Optional[int]
    delta_e_samples: int
    resolutions: tuple
    compile: bool
    every_row: bool
    peak_memory: bool

    @classmethod
    def of(cls, quick: bool, device: str = "cpu", out: Path = Path("benchmarks/out")) -> "Plan":
        """The full plan, or the quick one: the rows a choice hangs on (not ``every_row``), photographs at most
        :data:`QUICK_SIDE` pixels a side, fewer rounds, scaling up to 1024², no ``torch.compile``, no peak memory."""
        device, out = torch.device(device), Path(out)
        if not quick:
            return cls(quick=False, device=device, out=out, runs=11, scaling_runs=5, accuracy_side=None, delta_e_samples=200_000,
                       resolutions=RESOLUTIONS, compile=True, every_row=True, peak_memory=True)
        return cls(quick=True, device=device, out=out, runs=QUICK_RUNS, scaling_runs=3, accuracy_side=QUICK_SIDE,
                   delta_e_samples=20_000, resolutions=RESOLUTIONS[:3], compile=False, every_row=False, peak_memory=False)

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
        self.exports = {}  # ONNX files by model, exported once a run (benchmarks.suite.runtimes)
        self.baked_from = tg.PostFX.from_config(LOOK).eval()  # bake_lut evaluates on the CPU
        self.look = tg.PostFX.from_config(LOOK).to(plan.device).eval()
        self.per_pixel = self.look.per_pixel_stages()
        self.scenes = accuracy_scenes(plan)
        self.frame = tg.scene.demo_scene(*FRAME).to(plan.device)
        with torch.no_grad():
            reference = as_strip(self.look(scene.double()) for scene in self.scenes.values())
        self.reference_codes = metrics.srgb_codes(reference)
        pixels = self.reference_codes[0, 0].numel()
        self.delta_e_pixels = metrics.sample_indices(pixels, plan.delta_e_samples)

    @functools.lru_cache(maxsize=None)  # noqa: B019 (one workload a run: kept as long as its cache)
    def per_pixel_strip(self, dtype: torch.dtype) -> torch.Tensor:
        """The accuracy scenes as the per-pixel stage receives them (eye adaptation and bloom computed on ``dtype``
        input, :meth:`torchgrade.PostFX.per_pixel_input`), as one strip in ``dtype``."""
        with torch.no_grad():
            return as_strip(self.look.per_pixel_input(scene.to(dtype)) for scene in self.scenes.values())

    @functools.lru_cache(maxsize=None)  # noqa: B019 (one workload a run: kept as long as its cache)
    def per_pixel_frame(self, dtype: torch.dtype) -> torch.Tensor:
        """The 1920×1080 frame as the per-pixel stage receives it."""
        with torch.no_grad():
            return self.look.per_pixel_input(self.frame.to(dtype))

    @functools.lru_cache(maxsize=None)  # noqa: B019 (one workload a run: kept as long as its cache)
    def lut(self, size: int, shaper: str, fitted: bool = False) -> tg.LUT3D:
        """The per-pixel stage baked (in float64) into a ``size``³ LUT, table stored in float32.

        ``fitted``: the lattice reaches the brightest pixel the per-pixel stage receives from the accuracy scenes
        (``bake_lut(scene=...)``) instead of the shaper's default top.
        """
        scene = self.per_pixel_strip(torch.float32).cpu() if fitted else None
        baked = tg.bake_lut(self.baked_from.per_pixel_stages(), size=size, shaper=shaper, scene=scene)
        return float32_lut(baked).to(self.plan.device)

    @functools.cached_property
    def default_lut(self) -> tg.LUT3D:
        """``tg.bake_lut`` of the per-pixel stage with every default (size, lattice), table stored in float32."""
        return float32_lut(tg.bake_lut(self.baked_from.per_pixel_stages())).to(self.plan.device)

    @functools.cached_property
    def baked_look(self) -> tg.PostFX:
        """``look.to_lut()``: the look with its per-pixel stage baked by default, eye adaptation and bloom live."""
        return self.baked_from.to_lut().to(self.plan.device).eval()


def float32_lut(lut: tg.LUT3D, compile: bool = False) -> tg.LUT3D:
    """A copy of ``lut`` with its table in float32 (as served), optionally looked up through ``torch.compile``."""
    served = copy.deepcopy(lut)
    served.table = lut.table.detach().float()
    served.compile = compile
    return served
