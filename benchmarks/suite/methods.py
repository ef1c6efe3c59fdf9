"""The suite's methods: every way of computing the look's per-pixel stage (or the whole look), one row each.

Direct evaluation in four dtypes, baked LUTs (sizes, shapers, interpolations, fitted lattices),
``torch.compile``, onnxruntime on the exported model, and OpenColorIO's CPU processor on the same LUTs
written as .cube files. Part of ``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

import functools
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import torch
from torch import nn

import torchgrade as tg
from benchmarks.common import ocio_apply, ocio_in_place, ocio_processor
from benchmarks.suite.workload import LOOK, Workload, float32_lut

DEFAULT_SHAPER = "logc_extended"
"""The lattice ``PostFX.to_lut`` and ``bake_lut(shaper="auto")`` give an HDR look (LogC, then a tail to 65504)."""
DEFAULT_SIZE = 45
"""Its size when none is given: its rows are measured whatever the plan's sizes and shapers."""
HDR_UNUSABLE = "linear"
"""The shaper whose lattice clips everything above 1: its rows are kept in the table, never offered for HDR."""
INTERPOLATIONS = ("trilinear", "tetrahedral")
FITTED_SIZES = (33, 65)
"""Sizes also baked with the lattice reaching the scenes' brightest pixel (tetrahedral rows)."""
PEER = "OpenColorIO 33³ logc tetrahedral"
"""The row every per-pixel row's time is also divided by (the peer a colourist would use)."""


@dataclass
class Method:
    """One row: a way to compute the per-pixel stage (or the whole look, ``whole_look=True``).

    ``apply`` maps the row's input (the bloomed image, or the scene for a whole-look row) in ``dtype``
    to display-referred linear RGB. ``timer(frame)`` returns ``(run, reset)``: the timed call and an
    untimed call to run before each one (or ``None``); by default ``run`` is ``apply(frame)``.
    ``host`` rows run on the CPU whatever the device (onnxruntime, OpenColorIO).
    """

    name: str
    family: str
    apply: Callable[[torch.Tensor], torch.Tensor]
    dtype: torch.dtype = torch.float32
    whole_look: bool = False
    host: bool = False
    timer: Optional[Callable] = None
    info: dict = field(default_factory=dict)

    def timed_call(self, frame: torch.Tensor):
        return self.timer(frame) if self.timer else ((lambda: self.apply(frame)), None)


def direct_rows(work: Workload) -> list:
    dtypes = {"float64 (reference)": torch.float64, "float32": torch.float32,
              "bfloat16": torch.bfloat16, "float16": torch.float16}
    rows = [(f"direct {label}", functools.partial(Method, f"direct {label}", "direct", work.per_pixel, dtype))
            for label, dtype in dtypes.items()]
    name = "direct float32, whole look"
    rows.append((name, functools.partial(Method, name, "direct", work.look, whole_look=True)))
    return rows


def lut_name(size: int, shaper: str, interpolation: str) -> str:
    return f"LUT {size}³ {shaper} {interpolation}"


def fitted_lut_name(size: int) -> str:
    return f"LUT {size}³ logc tetrahedral, domain fitted to the scenes"


def lut_keys(sizes, shapers) -> list:
    return [(size, shaper, interpolation) for size in sizes for shaper in shapers for interpolation in INTERPOLATIONS]


def lut_rows(work: Workload) -> list:
    def build(size, shaper, interpolation):
        lut = work.lut(size, shaper)
        info = {"lut_size": size, "shaper": shaper, "interpolation": interpolation}
        return Method(lut_name(size, shaper, interpolation), "lut", lambda x: lut(x, interpolation), info=info)

    def build_fitted(size):
        lut = work.lut(size, "logc", fitted=True)
        top = float(tg.color.logc_to_linear(lut.domain_max.double()).max())
        info = {"lut_size": size, "shaper": "logc", "interpolation": "tetrahedral", "domain_top_linear": round(top, 1)}
        return Method(fitted_lut_name(size), "lut", lambda x: lut(x, "tetrahedral"), info=info)

    keys = lut_keys(work.plan.lut_sizes, work.plan.shapers) + lut_keys((DEFAULT_SIZE,), (DEFAULT_SHAPER,))
    rows = [(lut_name(*key), functools.partial(build, *key)) for key in dict.fromkeys(keys)]
    return rows + [(fitted_lut_name(size), functools.partial(build_fitted, size)) for size in FITTED_SIZES]


def compile_rows(work: Workload) -> list:
    """``torch.compile`` of the direct float32 stage and of the 33³ default-lattice lookups; compile time = first call at 1080p."""

    def build(name, module, interpolation=None):
        apply = (lambda x: module(x, interpolation)) if interpolation else module
        start = time.perf_counter()
        with torch.no_grad():
            apply(work.bloomed_frame(torch.float32))
        if isinstance(module, tg.LUT3D) and not module.compile:
            raise RuntimeError("torch.compile failed; LUT3D fell back to its eager lookup")
        return Method(name, "torch.compile", apply, info={"compile_s": round(time.perf_counter() - start, 1)})

    rows = [("torch.compile direct float32", lambda: build("torch.compile direct float32", torch.compile(work.per_pixel)))]
    for interpolation in INTERPOLATIONS:
        name = f"torch.compile {lut_name(DEFAULT_SIZE, DEFAULT_SHAPER, interpolation)}"
        rows.append((name, functools.partial(
            lambda n, i: build(n, float32_lut(work.lut(DEFAULT_SIZE, DEFAULT_SHAPER), compile=True), i), name, interpolation)))
    return rows


def onnx_session(path: Path):
    """onnxruntime CPU session, one intra-op thread per core, arena off (so peak memory is per run)."""
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = os.cpu_count()
    options.enable_cpu_mem_arena = False
    return onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def onnx_method(name: str, module: nn.Module, path: Path, whole_look: bool = False) -> Method:
    """Export ``module`` with :func:`torchgrade.onnx.export` and run it with onnxruntime."""
    start = time.perf_counter()
    tg.onnx.export(module.cpu(), path)
    export_s = round(time.perf_counter() - start, 1)
    session = onnx_session(path)

    def feed(image):
        return {"image": image.detach().cpu().float().numpy()}

    def apply(image):
        return torch.from_numpy(session.run(None, feed(image))[0])

    def timer(frame):
        feeds = feed(frame)
        return (lambda: session.run(None, feeds)), None

    return Method(name, "onnxruntime", apply, whole_look=whole_look, host=True, timer=timer,
                  info={"export_s": export_s, "onnx_nodes": tg.onnx.node_count(path)})


def onnx_rows(work: Workload) -> list:
    folder = work.folder
    look = tg.PostFX.from_config(LOOK)
    per_pixel = tg.PostFX(grade=LOOK["grade"], tonemap=LOOK["tonemap"])
    rows = [
        ("onnxruntime direct float32", lambda: onnx_method("onnxruntime direct float32", per_pixel, folder / "direct.onnx")),
        ("onnxruntime whole look", lambda: onnx_method("onnxruntime whole look", look, folder / "look.onnx", whole_look=True)),
    ]
    for interpolation in work.plan.onnx_lut_interpolations:
        name = f"onnxruntime {lut_name(DEFAULT_SIZE, DEFAULT_SHAPER, interpolation)}"
        rows.append((name, functools.partial(
            lambda n, i: onnx_method(n, tg.PostFX(lut=work.lut(DEFAULT_SIZE, DEFAULT_SHAPER), interpolation=i), folder / f"lut_{i}.onnx"),
            name, interpolation)))
    return rows


def opencolorio_method(work: Workload, size: int, shaper: str, interpolation: str) -> Method:
    """The LUT written with :func:`torchgrade.io.write_cube` and applied by OpenColorIO's CPU processor."""
    path = work.folder / f"look_{size}_{shaper}.cube"  # a fresh folder per run: OpenColorIO caches by path
    if not path.exists():
        tg.io.write_cube(path, work.lut(size, shaper))
    processor = ocio_processor(path, interpolation)
    info = {"lut_size": size, "shaper": shaper, "interpolation": interpolation}
    return Method(f"OpenColorIO {size}³ {shaper} {interpolation}", "opencolorio", functools.partial(ocio_apply, processor),
                  host=True, timer=functools.partial(ocio_in_place, processor), info=info)


def opencolorio_rows(work: Workload) -> list:
    keys = lut_keys(work.plan.opencolorio_sizes, work.plan.shapers)
    return [(f"OpenColorIO {size}³ {shaper} {interpolation}", functools.partial(opencolorio_method, work, size, shaper, interpolation))
            for size, shaper, interpolation in keys]


def method_rows(work: Workload) -> list:
    """Every row as ``(name, build)``; rows that need a CPU library are left out on other devices."""
    rows = direct_rows(work) + lut_rows(work)
    if work.plan.compile:
        rows += compile_rows(work)
    if work.plan.device.type == "cpu":
        rows += onnx_rows(work) + opencolorio_rows(work)
    return rows
