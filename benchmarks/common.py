"""What the benchmarks share: output folder and record, the interleaved timer, peak-memory readers, OpenColorIO, the sample EXRs.

Nothing here measures on its own; each benchmark says what it measures with these and how to run it
(for example ``.venv/bin/python -m benchmarks suite --quick``, which uses every part of this module).

Every benchmark that writes results takes ``--out DIR`` (:func:`argument_parser`), default ``benchmarks/out``
(git-ignored); the committed results in ``benchmarks/results`` change only with ``--out benchmarks/results``.
Each result records where it was measured (:func:`environment`: device, threads, load, versions).

Timing alternates the things compared (A B A B …: every round runs each once, each round starting one place
later), so a change of machine load during the run hits all of them alike and no call always follows the same
one, and reports medians. Peak memory is read from the kernel's
peak-RSS counter (Linux) or from CUDA's allocator statistics.
"""

from __future__ import annotations

import argparse
import ctypes
import functools
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch

import torchgrade as tg
from torchgrade.io.atomic import atomic_write

ROOT = Path(__file__).resolve().parents[1]
EXR_DIR = ROOT.parent / "shared" / "data" / "exr"
"""The OpenEXR project's sample images (BSD-3), shared beside the repository."""
RESULTS = ROOT / "benchmarks" / "results"
"""Where the committed results live; written only when a run is given ``--out benchmarks/results``."""
OUT = ROOT / "benchmarks" / "out"
"""Where a benchmark writes by default (git-ignored)."""
PEERS = {"onnxruntime": "onnxruntime", "PyOpenColorIO": "opencolorio", "kornia": "kornia", "openvino": "openvino"}
"""Peer libraries whose version a result records when the run imported them: module name -> record key."""


def argument_parser(doc: str, quick: Optional[str] = None) -> argparse.ArgumentParser:
    """A benchmark's parser, described by the first paragraph of its docstring ``doc``, with ``--out DIR``, and
    ``--quick`` where the benchmark has a quick form (``quick`` says what it leaves out; the benchmark's module states
    it as ``QUICK``, which ``python -m benchmarks --list`` shows)."""
    parser = argparse.ArgumentParser(description=" ".join(doc.strip().split("\n\n")[0].split()))
    parser.add_argument("--out", type=Path, default=OUT,
                        help="folder for the results (default benchmarks/out, git-ignored; "
                             "pass benchmarks/results to replace the committed results)")
    if quick:
        parser.add_argument("--quick", action="store_true", help=quick)
    return parser


def environment(device: str = "cpu") -> dict:
    """Where a result was measured: device, CPU and torch thread counts, load averages (1, 5, 15 min) now,
    and the versions of torch, torchgrade and every peer library this process imported."""
    versions = {"torch": torch.__version__, "torchgrade": tg.__version__}
    versions.update({key: sys.modules[module].__version__ for module, key in PEERS.items() if module in sys.modules})
    device_name = torch.cuda.get_device_name(device) if str(device).startswith("cuda") else platform.processor() or platform.machine()
    return {"device": str(device), "device_name": device_name, "cpu_count": os.cpu_count(),
            "torch_threads": torch.get_num_threads(), "load_average": [round(x, 2) for x in os.getloadavg()],
            "versions": versions, "platform": platform.platform()}


def environment_line(env: dict) -> str:
    """:func:`environment` as one markdown line."""
    versions = ", ".join(f"{name} {version}" for name, version in env["versions"].items())
    load = " / ".join(f"{x:.2f}" for x in env["load_average"])
    return (f"Measured on {env['device']} ({env['device_name']}), {env['cpu_count']} CPUs, {env['torch_threads']} torch threads, "
            f"load average {load} (1 / 5 / 15 min, at the end); {versions}.")


def _write_text(path: Path, text: str) -> None:
    """``text`` to ``path`` atomically: a reader, or a run stopped half-way, sees the old file or the whole new one."""
    atomic_write(path, lambda temporary: Path(temporary).write_text(text, encoding="utf-8"))


def write_markdown(out: Path, name: str, lines: list, device: str = "cpu") -> dict:
    """Write ``lines`` and a line of their :func:`environment` to ``out/<name>``; returns the environment."""
    env = environment(device)
    out.mkdir(parents=True, exist_ok=True)
    _write_text(out / name, "\n".join([*lines, "", environment_line(env)]) + "\n")
    return env


def write_results(out: Path, stem: str, report: dict, lines: list, command: str, device: str = "cpu", announce: bool = True) -> None:
    """Write ``lines`` to ``out/<stem>.md`` and ``report`` to ``out/<stem>.json``, each with its
    :func:`environment`, atomically; with ``announce``, print the table and ``command``."""
    env = write_markdown(out, f"{stem}.md", lines, device)
    _write_text(out / f"{stem}.json", json.dumps({**report, "environment": env}, indent=2, ensure_ascii=False) + "\n")
    if announce:
        print("\n".join(lines))
        print(f"\nwrote {out / stem}.json and .md; reproduce: {command}")


def mark_table(kind: str, name: str, table: list) -> list:
    """``table``'s lines between ``<!-- KIND:NAME -->`` and ``<!-- /KIND:NAME -->``: the marks by which
    ``python -m benchmarks suite --pages`` copies a table of committed results onto the page that quotes it
    (``benchmarks/suite/pages.py``).

    Examples:
        >>> mark_table("lut", "frames", ["| a |"])
        ['<!-- lut:frames -->', '| a |', '<!-- /lut:frames -->']
    """
    return [f"<!-- {kind}:{name} -->", *table, f"<!-- /{kind}:{name} -->"]


def sample_exr(name: str, to_rec709: bool = False) -> torch.Tensor:
    """The RGB of sample image ``name`` (e.g. ``"Desk"``) as a ``(1, 3, H, W)`` float32 tensor."""
    return tg.io.read_exr(EXR_DIR / f"{name}.exr", to_rec709=to_rec709)[:3].unsqueeze(0)


# ---------------------------------------------------------------- timing


def synchronizer(device: torch.device) -> Callable[[], None]:
    """A call that waits for ``device``'s queued work (CUDA runs asynchronously), a no-op on the CPU."""
    return (lambda: torch.cuda.synchronize(device)) if device.type == "cuda" else (lambda: None)


def run_and_reset(call) -> tuple:
    """A timer call (``run`` or ``(run, reset)``, see :func:`interleaved_ms`) as ``(run, reset or None)``."""
    return call if isinstance(call, tuple) else (call, None)


def interleaved_ms(calls: dict, runs: int, warmup: int = 1, sync: Optional[Callable[[], None]] = None) -> dict:
    """Wall times in ms, ``{name: [runs times]}``, of each call in ``calls``, every round running each call once,
    round ``k`` starting at the ``k``-th call (what ran just before a call, e.g. a large free, changes round to round).

    A call is ``run`` or ``(run, reset)``: ``reset`` (or None) runs untimed before each ``run``, e.g. to restore a
    buffer an in-place call overwrites. ``warmup`` untimed rounds come first. ``sync`` (see :func:`synchronizer`)
    brackets each timed call. Autograd is off; a call that times a backward pass turns it on itself.
    """
    sync = sync or (lambda: None)
    pairs = [(name, *run_and_reset(call)) for name, call in calls.items()]
    times = {name: [] for name in calls}
    with torch.no_grad():
        for attempt in range(warmup + runs):
            start_at = attempt % len(pairs)
            for name, run, reset in pairs[start_at:] + pairs[:start_at]:
                if reset:
                    reset()
                sync()
                start = time.perf_counter()
                run()
                sync()
                if attempt >= warmup:
                    times[name].append((time.perf_counter() - start) * 1000.0)
    return times


def median_ms(calls: dict, runs: int, warmup: int = 1, sync: Optional[Callable[[], None]] = None) -> dict:
    """Median ms of each call, ``{name: ms}``, timed by :func:`interleaved_ms`."""
    return {name: statistics.median(times) for name, times in interleaved_ms(calls, runs, warmup, sync).items()}


def median_ratio(times: dict, name: str, baseline: str) -> float:
    """The median over rounds of ``name``'s time over ``baseline``'s in the same round, from :func:`interleaved_ms`:
    a load change between rounds cancels in each ratio."""
    return statistics.median(ms / base for ms, base in zip(times[name], times[baseline]))


# ---------------------------------------------------------------- peak memory


def status_kib(field: str) -> int:
    """A ``/proc/self/status`` field in KiB, e.g. ``"VmRSS"`` (resident now) or ``"VmHWM"`` (peak resident)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


@functools.lru_cache(maxsize=None)
def _glibc():
    """glibc through ctypes, or None where there is no ``libc.so.6`` (not Linux with glibc)."""
    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        return None


def map_large_buffers() -> bool:
    """Make glibc serve every allocation above 64 KiB with its own mapping, returned to the system on free.

    Peak resident memory then rises and falls with each buffer, so :func:`peak_rss_mb` sees what a
    call allocates instead of heap pages kept from earlier calls. Slows allocation: call it after
    every timing. Returns False where glibc's ``mallopt`` is not available.
    """
    libc = _glibc()
    if libc is None:
        return False
    m_mmap_threshold, m_trim_threshold = -3, -1
    return bool(libc.mallopt(m_mmap_threshold, 65536)) and bool(libc.mallopt(m_trim_threshold, 0))


def release_free_memory() -> None:
    """Hand the heap's free pages back to the system (glibc ``malloc_trim``); a no-op without glibc."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


def peak_rss_mb(run) -> float | None:
    """Peak resident memory (MiB) that ``run()`` adds to the process, its output included.

    Free heap pages are released first, so reusing them counts as growth, and again after ``run``
    (the kernel updates its peak-RSS counter when pages are unmapped); the counter is reset before
    ``run`` through ``/proc/self/clear_refs``. ``None`` where that file is not available (not Linux).
    """
    release_free_memory()
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return None
    before = status_kib("VmRSS")
    run()
    release_free_memory()
    return max(0, status_kib("VmHWM") - before) / 1024.0


def peak_cuda_mb(run, device) -> float:
    """Peak CUDA memory (MiB) that ``run()`` allocates beyond what was allocated before."""
    torch.cuda.synchronize(device)
    torch.cuda.reset_peak_memory_stats(device)
    before = torch.cuda.memory_allocated(device)
    run()
    torch.cuda.synchronize(device)
    return (torch.cuda.max_memory_allocated(device) - before) / 2**20


# ---------------------------------------------------------------- OpenColorIO


def ocio_processor(cube_path, interpolation: str):
    """OpenColorIO's default CPU processor applying the .cube file at ``cube_path`` (``"trilinear"`` or ``"tetrahedral"``).

    OpenColorIO caches files by path: give each table its own path.
    """
    import PyOpenColorIO as OCIO

    mode = {"trilinear": OCIO.INTERP_LINEAR, "tetrahedral": OCIO.INTERP_TETRAHEDRAL}[interpolation]
    transform = OCIO.FileTransform(src=str(cube_path), interpolation=mode)
    return OCIO.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor()


def packed_rgb(image: torch.Tensor) -> np.ndarray:
    """A ``(1, 3, H, W)`` image as OpenColorIO's packed RGB float32 buffer ``(H, W, 3)``."""
    return np.ascontiguousarray(image.detach().cpu().float()[0].permute(1, 2, 0).numpy())


def ocio_apply(processor, image: torch.Tensor) -> torch.Tensor:
    """``processor`` applied to a ``(1, 3, H, W)`` image, as a new ``(1, 3, H, W)`` float32 tensor."""
    buffer = packed_rgb(image)
    processor.applyRGB(buffer)
    return torch.from_numpy(buffer).permute(2, 0, 1).unsqueeze(0)


def ocio_look(image: torch.Tensor) -> torch.Tensor:
    """A look made by OpenColorIO alone, for ``tg.match_look`` to learn: its ``GradingPrimaryTransform`` (linear style:
    exposure +0.2 with a per-channel tilt of ±0.1, contrast 1.1, an offset of 0.002 in blue, saturation 1.1) then its
    built-in ACES 1.0 SDR view (studio config 2.2.0), on a scene-linear Rec.709 ``(3, H, W)`` image.

    Returns the display-linear ``(3, H, W)`` float64 picture (the view's sRGB output clipped to [0, 1] and decoded).
    """
    import PyOpenColorIO as OCIO

    primary = OCIO.GradingPrimary(OCIO.GRADING_LIN)
    primary.exposure = OCIO.GradingRGBM(0.1, 0.0, -0.1, 0.2)
    primary.contrast = OCIO.GradingRGBM(1.0, 1.0, 1.0, 1.1)
    primary.offset = OCIO.GradingRGBM(0.0, 0.0, 0.002, 0.0)
    primary.saturation = 1.1
    grade = OCIO.Config.CreateRaw().getProcessor(OCIO.GradingPrimaryTransform(primary, OCIO.GRADING_LIN, False))
    config = OCIO.Config.CreateFromBuiltinConfig("studio-config-v2.2.0_aces-v1.3_ocio-v2.4")
    view = config.getProcessor("Linear Rec.709 (sRGB)", "sRGB - Display", "ACES 1.0 - SDR Video", OCIO.TRANSFORM_DIR_FORWARD)
    graded = ocio_apply(grade.getDefaultCPUProcessor(), image[None])
    shown = ocio_apply(view.getDefaultCPUProcessor(), graded)[0]
    return tg.color.srgb_to_linear(shown.clamp(0.0, 1.0).double())


def ocio_in_place(processor, image: torch.Tensor) -> tuple:
    """``(run, reset)`` for the timer: ``processor`` applied in place to a packed copy of ``image``, which
    ``reset`` restores (untimed), so every run sees the same input."""
    source = packed_rgb(image)
    buffer = source.copy()
    return (lambda: processor.applyRGB(buffer)), (lambda: np.copyto(buffer, source))
