"""The benchmark suite: every way torchgrade (and its peers) can compute one strong look, for speed and accuracy.

    .venv/bin/python benchmarks/run.py [--quick] [--device cpu|cuda] [--out DIR]

**The look** (:data:`LOOK`): scattering bloom, an ACES-space grade (exposure, temperature, contrast,
saturation, split toning) and the ACES tone mapper. Bloom looks at neighbouring pixels, so it always
runs live; the *per-pixel stage* (grade + tone map) is what the methods compute in different ways.

**Rows** (:func:`method_rows`): the per-pixel stage computed directly in float64 (the reference),
float32, bfloat16 and float16 (the library computes half inputs in float32: those rows measure the
conversion and the quantisation of half inputs); baked into LUTs of 9, 17, 33 and 65 points per axis,
linear or LogC shaper, trilinear or tetrahedral lookup (plus 33³ and 65³ LogC LUTs whose lattice
reaches the scenes' brightest pixel, ``bake_lut(scene=...)``, instead of LogC 1.0 ≈ 58.9);
``torch.compile``d (full run only; a row whose compilation fails records why); exported to ONNX and
run by onnxruntime; and the same LUTs written as .cube files and applied by OpenColorIO's CPU processor. Two *whole-look* rows (bloom included) compare PyTorch and onnxruntime on the exported look.

**Accuracy** is measured on the whole look: the scene goes through bloom (in the row's dtype) and the
row's per-pixel stage, and is compared with the float64 look, on the sample EXRs (Desk, CandleGlass,
GoldenGate, BrightRings) and the procedural demo scene, pooled: max and 99.9th percentile absolute
error in 8-bit sRGB code values over every channel of every pixel, and mean ΔE2000 over a fixed random
sample of pixels (see :mod:`benchmarks.metrics`). ``--quick`` measures on images area-downscaled to
at most 400 pixels a side.

**Speed** is the timed part of each row (its ``timed`` field: the per-pixel stage, or the whole look)
on the demo scene rendered at 1920×1080 (bloomed first for per-pixel rows), median of repeated runs
after a warm-up, in ms per megapixel and as ratios to a plain copy of the frame (the memory floor)
and to OpenColorIO's 33³ LogC tetrahedral processor, all measured in this one run. OpenColorIO is
timed on its in-place apply (the buffer is restored between runs, untimed); onnxruntime on
``session.run`` with the image already in a numpy array, ``intra_op_num_threads`` = CPU count.
Bloom, the part every look pays on top of a per-pixel row, is timed on its own (``baselines``).

**Peak memory** is what the timed part adds to the process at 1920×1080, its output included, after
every timing is done: CPU peak resident memory with every buffer above 64 KiB given its own mapping
(:func:`benchmarks.metrics.map_large_buffers`) and onnxruntime's arena switched off; CUDA peak
allocated memory on a GPU.

**Scaling**: the direct float32 and the 33³ LogC tetrahedral LUT per-pixel stages from 256² to
3840×2160 (4K skipped under ``--quick``) and at batch sizes 1, 2, 4, 8 of 512².

Writes ``results.json``, ``results.md``, ``pareto.png`` and ``scaling.png`` to ``--out``.
"""

from __future__ import annotations

import argparse
import copy
import functools
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import torchgrade as tg  # noqa: E402
from benchmarks import metrics  # noqa: E402
from torchgrade.lut import LUT3D  # noqa: E402

LOOK = {
    "bloom": {"mode": "scattering", "threshold": 1.0, "knee": 0.5, "intensity": 0.6, "scatter": 0.7},
    "grade": {"aces": True, "post_exposure": 0.5, "temperature": 20, "contrast": 30, "saturation": 20,
              "split_shadows": [0.42, 0.5, 0.6], "split_highlights": [0.6, 0.5, 0.42]},
    "tonemap": {"mode": "aces"},
}
EXR_DIR = ROOT.parent / "shared" / "data" / "exr"
EXR_NAMES = ("Desk", "CandleGlass", "GoldenGate", "BrightRings")
DEMO_SIZE = (720, 1280)
FRAME = (1080, 1920)
LUT_SIZES = (9, 17, 33, 65)
SHAPERS = ("linear", "logc")
INTERPOLATIONS = ("trilinear", "tetrahedral")
FITTED_SIZES = (33, 65)
"""Sizes also baked with the lattice reaching the scenes' brightest pixel (tetrahedral rows)."""
PEER = "OpenColorIO 33³ logc tetrahedral"
"""The row every per-pixel row's time is also divided by (the peer a colourist would use)."""
RESOLUTIONS = ((256, 256), (512, 512), (1024, 1024), (1080, 1920), (2160, 3840))
BATCHES = (1, 2, 4, 8)
BATCH_SIDE = 512


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

    @classmethod
    def from_args(cls, args) -> "Plan":
        quick = args.quick
        default_out = ROOT / "benchmarks" / "results" / ("quick" if quick else "full")
        return cls(
            quick=quick,
            device=torch.device(args.device),
            out=Path(args.out) if args.out else default_out,
            runs=2 if quick else 5,
            scaling_runs=3,
            accuracy_side=400 if quick else None,
            delta_e_samples=20_000 if quick else 200_000,
            resolutions=RESOLUTIONS[:-1] if quick else RESOLUTIONS,
            compile=not quick,
        )

    def command(self) -> str:
        return ".venv/bin/python benchmarks/run.py" + (" --quick" if self.quick else "") + f" --device {self.device.type}"


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


# ---------------------------------------------------------------- inputs


def downscale(image: torch.Tensor, max_side: Optional[int]) -> torch.Tensor:
    """Area-average ``image`` by the smallest integer factor that brings its longer side to ``max_side``."""
    factor = 1 if max_side is None else -(-max(image.shape[-2:]) // max_side)
    return image if factor == 1 else nn.functional.avg_pool2d(image, factor, ceil_mode=True)


def accuracy_scenes(plan: Plan) -> dict:
    """The images accuracy is measured on: the sample EXRs (RGB, Rec.709) and the demo scene, ``(1, 3, H, W)``."""
    scenes = {name: tg.io.read_exr(EXR_DIR / f"{name}.exr", to_rec709=True)[:3].unsqueeze(0) for name in EXR_NAMES}
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
    def lut(self, size: int, shaper: str, fitted: bool = False) -> LUT3D:
        """The per-pixel stage baked (in float64) into a ``size``³ LUT, table stored in float32.

        ``fitted``: the lattice reaches the brightest bloomed pixel of the accuracy scenes
        (``bake_lut(scene=...)``) instead of the shaper's default top (LogC 1.0, linear ≈ 58.9).
        """
        scene = self.bloomed_strip(torch.float32).cpu() if fitted else None
        baked = tg.bake_lut(self.per_pixel, size=size, shaper=shaper, scene=scene)
        return float32_lut(baked).to(self.plan.device)

    def timing_input(self, method: Method) -> torch.Tensor:
        return self.frame.to(method.dtype) if method.whole_look else self.bloomed_frame(method.dtype)


def float32_lut(lut: LUT3D, compile: bool = False) -> LUT3D:
    """A copy of ``lut`` with its table in float32 (as served), optionally looked up through ``torch.compile``."""
    served = copy.deepcopy(lut)
    served.table = lut.table.detach().float()
    served.compile = compile
    return served


# ---------------------------------------------------------------- rows


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

    rows = [(lut_name(*key), functools.partial(build, *key)) for key in lut_keys()]
    return rows + [(fitted_lut_name(size), functools.partial(build_fitted, size)) for size in FITTED_SIZES]


def fitted_lut_name(size: int) -> str:
    return f"LUT {size}³ logc tetrahedral, domain fitted to the scenes"


def lut_keys() -> list:
    return [(size, shaper, interpolation) for size in LUT_SIZES for shaper in SHAPERS for interpolation in INTERPOLATIONS]


def compile_rows(work: Workload) -> list:
    """``torch.compile`` of the direct float32 stage and of the 33³ LogC lookups; compile time = first call at 1080p."""

    def build(name, module, interpolation=None):
        apply = (lambda x: module(x, interpolation)) if interpolation else module
        start = time.perf_counter()
        with torch.no_grad():
            apply(work.bloomed_frame(torch.float32))
        if isinstance(module, LUT3D) and not module.compile:
            raise RuntimeError("torch.compile failed; LUT3D fell back to its eager lookup")
        return Method(name, "torch.compile", apply, info={"compile_s": round(time.perf_counter() - start, 1)})

    rows = [("torch.compile direct float32", lambda: build("torch.compile direct float32", torch.compile(work.per_pixel)))]
    for interpolation in INTERPOLATIONS:
        name = f"torch.compile {lut_name(33, 'logc', interpolation)}"
        rows.append((name, functools.partial(
            lambda n, i: build(n, float32_lut(work.lut(33, "logc"), compile=True), i), name, interpolation)))
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
    for interpolation in INTERPOLATIONS:
        name = f"onnxruntime {lut_name(33, 'logc', interpolation)}"
        rows.append((name, functools.partial(
            lambda n, i: onnx_method(n, tg.PostFX(lut=work.lut(33, "logc"), interpolation=i), folder / f"lut_{i}.onnx"),
            name, interpolation)))
    return rows


def packed_rgb(image: torch.Tensor) -> np.ndarray:
    """A ``(1, 3, H, W)`` image as OpenColorIO's packed RGB float32 buffer ``(H, W, 3)``."""
    return np.ascontiguousarray(image.detach().cpu().float()[0].permute(1, 2, 0).numpy())


def opencolorio_method(work: Workload, size: int, shaper: str, interpolation: str) -> Method:
    """The LUT written with :func:`torchgrade.io.write_cube` and applied by OpenColorIO's CPU processor."""
    import PyOpenColorIO as OCIO

    path = work.folder / f"look_{size}_{shaper}.cube"  # a fresh folder per run: OpenColorIO caches by path
    if not path.exists():
        tg.io.write_cube(path, work.lut(size, shaper))
    mode = {"trilinear": OCIO.INTERP_LINEAR, "tetrahedral": OCIO.INTERP_TETRAHEDRAL}[interpolation]
    transform = OCIO.FileTransform(src=str(path), interpolation=mode)
    processor = OCIO.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor()

    def apply(image):
        buffer = packed_rgb(image)
        processor.applyRGB(buffer)
        return torch.from_numpy(buffer).permute(2, 0, 1).unsqueeze(0)

    def timer(frame):
        source = packed_rgb(frame)
        buffer = source.copy()
        return (lambda: processor.applyRGB(buffer)), (lambda: np.copyto(buffer, source))

    info = {"lut_size": size, "shaper": shaper, "interpolation": interpolation}
    return Method(f"OpenColorIO {size}³ {shaper} {interpolation}", "opencolorio", apply, host=True, timer=timer, info=info)


def opencolorio_rows(work: Workload) -> list:
    return [(f"OpenColorIO {size}³ {shaper} {interpolation}", functools.partial(opencolorio_method, work, size, shaper, interpolation))
            for size, shaper, interpolation in lut_keys()]


def method_rows(work: Workload) -> list:
    """Every row as ``(name, build)``; rows that need a CPU library are left out on other devices."""
    rows = direct_rows(work) + lut_rows(work)
    if work.plan.compile:
        rows += compile_rows(work)
    if work.plan.device.type == "cpu":
        rows += onnx_rows(work) + opencolorio_rows(work)
    return rows


# ---------------------------------------------------------------- measuring


def synchronizer(device: torch.device) -> Callable[[], None]:
    return (lambda: torch.cuda.synchronize(device)) if device.type == "cuda" else (lambda: None)


def median_ms(run: Callable, reset: Optional[Callable], runs: int, sync: Callable[[], None]) -> float:
    """Median wall time (ms) of ``runs`` calls of ``run`` after one warm-up; ``reset`` runs untimed before each."""
    times = []
    for attempt in range(runs + 1):
        if reset:
            reset()
        sync()
        start = time.perf_counter()
        run()
        sync()
        if attempt:
            times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times)


def accuracy(work: Workload, method: Method) -> dict:
    """Errors of ``method``'s whole look on the accuracy scenes against the float64 look (see the module docstring)."""
    with torch.no_grad():
        if method.whole_look:
            output = as_strip(method.apply(scene.to(method.dtype)) for scene in work.scenes.values())
        else:
            output = method.apply(work.bloomed_strip(method.dtype))
    codes = metrics.srgb_codes(output.reshape(work.reference_codes.shape))
    summary = metrics.code_error_summary(work.reference_codes, codes)
    reference, sample = (sampled(c, work.delta_e_pixels) for c in (work.reference_codes, codes))
    summary["mean_delta_e2000"] = float(np.mean(metrics.delta_e2000(reference, sample)))
    return summary


def sampled(strip: torch.Tensor, indices: torch.Tensor) -> torch.Tensor:
    """The pixels ``indices`` of a ``(1, 3, 1, P)`` strip, as a strip."""
    return strip[..., indices]


def speed(work: Workload, method: Method) -> float:
    run, reset = method.timed_call(work.timing_input(method))
    with torch.no_grad():
        return median_ms(run, reset, work.plan.runs, synchronizer(work.plan.device))


def measure_row(work: Workload, name: str, build: Callable[[], Method]):
    """Build and measure one row; a row that fails records its error instead of stopping the run."""
    try:
        method = build()
        record = {"method": name, "family": method.family, "dtype": str(method.dtype).replace("torch.", ""),
                  "timed": "whole look" if method.whole_look else "per-pixel stage",
                  "device": "cpu" if method.host else work.plan.device.type, **method.info}
        record.update(accuracy(work, method))
        record["ms"] = speed(work, method)
        return method, record
    except Exception as error:  # noqa: BLE001 — e.g. torch.compile without a working compiler
        return None, {"method": name, "error": f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"}


def baselines(work: Workload) -> dict:
    """Timed-only references: the plain frame copy (the memory floor) and bloom, which every look adds."""
    sync = synchronizer(work.plan.device)
    frame = work.frame
    calls = {
        "plain frame copy": lambda: frame.clone(),
        "bloom float32": lambda: work.look.bloom(frame),
        "bloom float64": lambda: work.look.bloom(work.frame.double()),
    }
    with torch.no_grad():
        return {name: median_ms(call, None, work.plan.runs, sync) for name, call in calls.items()}


def add_ratios(records: list, base: dict) -> None:
    """ms per megapixel at 1920×1080, and ratios to the frame copy and (per-pixel rows) to OpenColorIO."""
    megapixels = FRAME[0] * FRAME[1] / 1e6
    peer = next((r["ms"] for r in records if r["method"] == PEER and "ms" in r), None)
    for record in records:
        if "ms" not in record:
            continue
        record["ms_per_megapixel"] = record["ms"] / megapixels
        record["ratio_to_copy"] = record["ms"] / base["plain frame copy"]
        per_pixel = record["timed"] == "per-pixel stage"
        record["ratio_to_opencolorio"] = record["ms"] / peer if peer and per_pixel else None


def peak_memory(work: Workload, method: Method) -> Optional[float]:
    run, reset = method.timed_call(work.timing_input(method))
    if reset:
        reset()
    with torch.no_grad():
        if work.plan.device.type == "cuda" and not method.host:
            return metrics.peak_cuda_mb(run, work.plan.device)
        return metrics.peak_rss_mb(run)


def scaling(work: Workload) -> list:
    """ms and ms per megapixel of the direct float32 and 33³ LogC tetrahedral stages by resolution and by batch."""
    lut = work.lut(33, "logc")
    paths = {"direct float32": work.per_pixel, lut_name(33, "logc", "tetrahedral"): lambda x: lut(x, "tetrahedral")}
    shapes = [("resolution", 1, h, w) for h, w in work.plan.resolutions]
    shapes += [("batch", b, BATCH_SIDE, BATCH_SIDE) for b in BATCHES]
    sync = synchronizer(work.plan.device)
    points = []
    for kind, batch, height, width in tqdm(shapes, desc="scaling", unit="shape"):
        image = tg.scene.demo_scene(height, width).to(work.plan.device).expand(batch, -1, -1, -1).contiguous()
        for path, apply in paths.items():
            with torch.no_grad():
                ms = median_ms(lambda: apply(image), None, work.plan.scaling_runs, sync)
            points.append({"path": path, "kind": kind, "batch": batch, "height": height, "width": width, "ms": ms,
                           "ms_per_megapixel": ms / (batch * height * width / 1e6)})
    return points


# ---------------------------------------------------------------- reporting


def fmt(value, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def row_note(record: dict) -> str:
    notes = []
    if "domain_top_linear" in record:
        notes.append(f"lattice up to linear {record['domain_top_linear']:g}")
    if "compile_s" in record:
        notes.append(f"compile {record['compile_s']:.0f} s")
    if "export_s" in record:
        notes.append(f"export {record['export_s']:.0f} s, {record['onnx_nodes']} nodes")
    if "error" in record:
        notes.append(f"failed: {record['error']}")
    return "; ".join(notes)


def markdown_table(records: list) -> str:
    lines = ["| method | timed | ms/MP | × copy | × OCIO | p99.9 err (8-bit) | max err (8-bit) | mean ΔE2000 | peak MiB | note |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for r in records:
        lines.append(
            f"| {r['method']} | {r.get('timed', '')} | {fmt(r.get('ms_per_megapixel'), 1)} | {fmt(r.get('ratio_to_copy'), 1)} | "
            f"{fmt(r.get('ratio_to_opencolorio'))} | {fmt(r.get('p999_error_8bit'))} | {fmt(r.get('max_error_8bit'))} | "
            f"{fmt(r.get('mean_delta_e2000'), 3)} | {fmt(r.get('peak_memory_mb'), 0)} | {row_note(r)} |")
    return "\n".join(lines)


def markdown(report: dict) -> str:
    megapixels = FRAME[0] * FRAME[1] / 1e6
    base = ", ".join(f"{name} {ms / megapixels:.1f} ms/MP" for name, ms in report["baselines"].items())
    m = report["machine"]
    return "\n".join([
        f"# torchgrade benchmark ({'quick' if report['quick'] else 'full'}, {report['device']})",
        "",
        f"`{report['command']}` — {m['cpu_count']} CPUs, {m['torch_threads']} torch threads, torch {m['torch']}, "
        f"onnxruntime {m['onnxruntime']}, OpenColorIO {m['opencolorio']}; {report['wall_s']:.0f} s in all.",
        "",
        "Speed: the timed part of each row on a 1920×1080 frame, median of "
        f"{report['runs']} runs; × copy and × OCIO are ratios to a plain frame copy and to {PEER}, measured in this run. "
        f"Per-pixel rows exclude bloom, which every look adds: {base}.",
        f"Accuracy: the whole look on {', '.join(report['scenes'])} against the float64 look; "
        f"ΔE2000 over {report['delta_e_samples']} sampled pixels. Peak MiB: memory the timed part adds at 1920×1080.",
        "",
        markdown_table(report["rows"]),
        "",
    ])


def family_colours() -> dict:
    return {"direct": "tab:blue", "lut": "tab:orange", "torch.compile": "tab:green", "onnxruntime": "tab:purple",
            "opencolorio": "tab:red"}


ERROR_FLOOR = 1e-3
"""Errors below this (the float64 reference's 0) are drawn at it on the log axis."""


def pareto_front(points: list) -> list:
    """The points no other point beats in both time and error, fastest first: ``[(ms, error, name), ...]``."""
    front, best = [], float("inf")
    for ms, error, name in sorted(points):
        if error < best:
            front.append((ms, error, name))
            best = error
    return front


def plot_pareto(records: list, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 6), dpi=90)
    points = []
    for family, colour in family_colours().items():
        rows = [r for r in records if r.get("family") == family and r.get("timed") == "per-pixel stage" and "ms" in r]
        xs = [r["ms_per_megapixel"] for r in rows]
        ys = [max(r["p999_error_8bit"], ERROR_FLOOR) for r in rows]
        ax.scatter(xs, ys, s=22, color=colour, label=family, alpha=0.8)
        points += [(x, y, r["method"]) for x, y, r in zip(xs, ys, rows)]
    front = pareto_front(points)
    ax.plot([p[0] for p in front], [p[1] for p in front], color="black", lw=1, ls="--", label="Pareto front")
    for rank, (ms, error, name) in enumerate(front):  # staggered: front points often share an error
        ax.annotate(name, (ms, error), fontsize=7, xytext=(4, 3 - 10 * (rank % 4)), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("per-pixel stage, ms per megapixel at 1920×1080 (log)")
    ax.set_ylabel(f"whole look, 99.9th percentile error, 8-bit sRGB codes (log; 0 drawn at {ERROR_FLOOR})")
    ax.set_title("Speed vs accuracy of the look's per-pixel stage")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_scaling(points: list, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_size, by_batch) = plt.subplots(1, 2, figsize=(10, 4), dpi=90)
    for name in dict.fromkeys(p["path"] for p in points):
        sizes = [p for p in points if p["path"] == name and p["kind"] == "resolution"]
        batches = [p for p in points if p["path"] == name and p["kind"] == "batch"]
        by_size.plot([p["height"] * p["width"] / 1e6 for p in sizes], [p["ms"] for p in sizes], marker="o", label=name)
        by_batch.plot([p["batch"] for p in batches], [p["ms_per_megapixel"] for p in batches], marker="o", label=name)
    by_size.set(xscale="log", yscale="log", xlabel="megapixels (256² … largest)", ylabel="ms per frame", title="time vs resolution")
    by_batch.set(xscale="log", xlabel=f"batch size ({BATCH_SIDE}²)", ylabel="ms per megapixel", title="time vs batch size")
    by_batch.set_xticks(BATCHES, [str(b) for b in BATCHES])
    by_batch.set_xticks([], minor=True)  # no "3×10⁰" labels between the batch sizes
    by_batch.set_ylim(bottom=0)
    for ax in (by_size, by_batch):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def machine() -> dict:
    import onnxruntime
    import PyOpenColorIO as OCIO

    return {"cpu_count": os.cpu_count(), "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
            "onnxruntime": onnxruntime.__version__, "opencolorio": OCIO.__version__, "platform": platform.platform()}


# ---------------------------------------------------------------- main


def measure_rows(work: Workload) -> tuple:
    """Accuracy and speed of every row, with a progress bar; returns the built methods and their records."""
    methods, records = {}, []
    rows = method_rows(work)
    bar = tqdm(rows, desc="rows", unit="row")
    for name, build in bar:
        bar.set_postfix_str(name)
        method, record = measure_row(work, name, build)
        records.append(record)
        if method is not None:
            methods[name] = method
    return methods, records


def record_peak_memory(work: Workload, methods: dict, records: list) -> None:
    """Peak memory of every built row, after all timing (the allocator setting slows allocation)."""
    metrics.map_large_buffers()
    for record in tqdm(records, desc="memory", unit="row"):
        if record["method"] in methods:
            record["peak_memory_mb"] = peak_memory(work, methods[record["method"]])


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller accuracy images, fewer runs, no torch.compile, no 4K")
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--out", help="output folder (default benchmarks/results/full, or .../quick with --quick)")
    plan = Plan.from_args(parser.parse_args(argv))
    started = time.perf_counter()
    torch.manual_seed(0)
    plan.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="torchgrade-bench-") as folder:
        work = Workload(plan, Path(folder))
        base = baselines(work)
        methods, records = measure_rows(work)
        add_ratios(records, base)
        points = scaling(work)
        record_peak_memory(work, methods, records)
    report = {
        "command": plan.command(), "quick": plan.quick, "device": plan.device.type, "look": LOOK,
        "frame": list(FRAME), "runs": plan.runs, "statistic": "median", "scenes": list(work.scenes),
        "accuracy_sizes": {name: list(image.shape[-2:]) for name, image in work.scenes.items()},
        "delta_e_samples": int(work.delta_e_pixels.numel()), "machine": machine(),
        "baselines": base, "rows": records, "scaling": points,
        "wall_s": time.perf_counter() - started,
    }
    (plan.out / "results.json").write_text(json.dumps(report, indent=2, ensure_ascii=False) + "\n")
    (plan.out / "results.md").write_text(markdown(report), encoding="utf-8")
    plot_pareto(records, plan.out / "pareto.png")
    plot_scaling(points, plan.out / "scaling.png")
    print(markdown(report))
    return report


if __name__ == "__main__":
    main()
