"""The suite's measurements: each row's accuracy on the scenes, its speed and peak memory at 1920×1080, and scaling.

Accuracy pools the scenes against the float64 look (8-bit sRGB code errors, mean ΔE2000 on sampled pixels).
Speed times every row and baseline in one session, alternated (each round runs each once,
:func:`benchmarks.common.interleaved_ms`): medians, and ratios as medians of each round's ratio. Part of
``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

import statistics
from typing import Callable, Optional

import numpy as np
import torch
from tqdm import tqdm

import torchgrade as tg
from benchmarks import common, metrics
from benchmarks.suite import workload
from benchmarks.suite.methods import PEER, PER_PIXEL, WHOLE_LOOK, method_rows
from benchmarks.suite.rows import Method, default_name
from benchmarks.suite.workload import Workload, as_strip


def timing_input(work: Workload, method: Method) -> torch.Tensor:
    """The 1920×1080 frame a row is timed on: the scene for a whole-look row, else the frame as the per-pixel stage
    receives it."""
    return work.frame.to(method.dtype) if method.whole_look else work.per_pixel_frame(method.dtype)


def accuracy(work: Workload, method: Method) -> dict:
    """Errors of ``method``'s whole look on the accuracy scenes against the float64 look (see ``benchmarks/run.py``)."""
    with torch.no_grad():
        if method.whole_look:
            output = as_strip(method.apply(scene.to(method.dtype)) for scene in work.scenes.values())
        else:
            output = method.apply(work.per_pixel_strip(method.dtype))
    codes = metrics.srgb_codes(output.reshape(work.reference_codes.shape))
    summary = metrics.code_error_summary(work.reference_codes, codes)
    reference, sample = (c[..., work.delta_e_pixels] for c in (work.reference_codes, codes))
    summary["mean_delta_e2000"] = float(np.mean(metrics.delta_e2000(reference, sample)))
    return summary


def measure_row(work: Workload, name: str, build: Callable[[], Method]):
    """Build one row and measure its accuracy; a row that fails records its error instead of stopping the run."""
    try:
        method = build()
        record = {"method": name, "family": method.family, "dtype": str(method.dtype).replace("torch.", ""),
                  "timed": "whole look" if method.whole_look else "per-pixel stage",
                  "device": "cpu" if method.host else work.plan.device.type, "headline": method.headline, **method.info}
        record.update(accuracy(work, method))
        return method, record
    except Exception as error:  # noqa: BLE001 — e.g. torch.compile without a working compiler
        return None, {"method": name, "error": f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"}


def measure_rows(work: Workload) -> tuple:
    """Accuracy of every row, with a progress bar; returns the built methods and their records."""
    methods, records = {}, []
    bar = tqdm(method_rows(work), desc="rows", unit="row")
    for name, build in bar:
        bar.set_postfix_str(name)
        method, record = measure_row(work, name, build)
        records.append(record)
        if method is not None:
            methods[name] = method
    return methods, records


COPY, LIVE, LIVE64 = "plain frame copy", "eye adaptation + bloom float32", "eye adaptation + bloom float64"


def baseline_calls(work: Workload) -> dict:
    """Timed-only references: the plain frame copy (the memory floor) and the live stages before the per-pixel stage
    (eye adaptation and bloom), which every row but the whole-look ones leaves out; in float64 too in the full run."""
    frame, live = work.frame, work.look.per_pixel_input
    calls = {COPY: lambda: frame.clone(), LIVE: lambda: live(frame)}
    if work.plan.every_row:
        frame64 = frame.double()
        calls[LIVE64] = lambda: live(frame64)
    return calls


def time_rows(work: Workload, methods: dict) -> dict:
    """ms of every round, ``{name: [ms, ...]}``, of the baselines and every built row, all alternated in one session.

    Timed apart, each row met its own machine load: on a shared machine the whole look once came out faster than
    its own per-pixel part. Alternated, a load change hits every row in the same rounds.
    """
    calls = baseline_calls(work)
    calls.update({name: method.timed_call(timing_input(work, method)) for name, method in methods.items()})
    print(f"timing {len(calls)} rows and baselines, alternated, {work.plan.runs} rounds after a warm-up", flush=True)
    return common.interleaved_ms(calls, work.plan.runs, sync=common.synchronizer(work.plan.device))


def add_speed(records: list, times: dict) -> dict:
    """ms, ms per megapixel at 1920×1080, and ratios to the frame copy and (per-pixel rows) to OpenColorIO, from
    :func:`time_rows`; returns the baselines' median ms."""
    megapixels = workload.FRAME[0] * workload.FRAME[1] / 1e6
    for record in records:
        name = record["method"]
        if name not in times:
            continue
        record["ms"] = statistics.median(times[name])
        record["ms_per_megapixel"] = record["ms"] / megapixels
        record["ratio_to_copy"] = common.median_ratio(times, name, COPY)
        per_pixel = record["timed"] == "per-pixel stage"
        record["ratio_to_opencolorio"] = common.median_ratio(times, name, PEER) if PEER in times and per_pixel else None
    return {name: statistics.median(times[name]) for name in (COPY, LIVE, LIVE64) if name in times}


def peak_memory(work: Workload, method: Method) -> Optional[float]:
    run, reset = method.timed_call(timing_input(work, method))
    if reset:
        reset()
    with torch.no_grad():
        if work.plan.device.type == "cuda" and not method.host:
            return common.peak_cuda_mb(run, work.plan.device)
        return common.peak_rss_mb(run)


def record_peak_memory(work: Workload, methods: dict, records: list) -> None:
    """Peak memory of every built row, after all timing (the allocator setting slows allocation)."""
    common.map_large_buffers()
    for record in tqdm(records, desc="memory", unit="row"):
        if record["method"] in methods:
            record["peak_memory_mb"] = peak_memory(work, methods[record["method"]])


def scaling(work: Workload) -> list:
    """ms and ms per megapixel of the direct float32 stage and the default bake's tetrahedral lookup by resolution and
    by batch."""
    lut = work.default_lut
    paths = {PER_PIXEL: work.per_pixel, default_name(lut, "tetrahedral"): lambda x: lut(x, "tetrahedral")}
    shapes = [("resolution", 1, h, w) for h, w in work.plan.resolutions]
    shapes += [("batch", b, workload.BATCH_SIDE, workload.BATCH_SIDE) for b in workload.BATCHES]
    sync = common.synchronizer(work.plan.device)
    points = []
    for kind, batch, height, width in tqdm(shapes, desc="scaling", unit="shape"):
        image = tg.scene.demo_scene(height, width).to(work.plan.device).expand(batch, -1, -1, -1).contiguous()
        calls = {path: (lambda apply=apply, image=image: apply(image)) for path, apply in paths.items()}
        for path, ms in common.median_ms(calls, work.plan.scaling_runs, sync=sync).items():
            points.append({"path": path, "kind": kind, "batch": batch, "height": height, "width": width, "ms": ms,
                           "ms_per_megapixel": ms / (batch * height * width / 1e6)})
    return points



def whole_look_check(times: dict) -> Optional[dict]:
    """The eager whole look against its parts timed in the same rounds: median ms of each, and the median over
    rounds of whole look / (live stages + per-pixel stage), which should not fall below 1. None if a part is missing."""
    names = (WHOLE_LOOK, PER_PIXEL, LIVE)
    if not all(name in times for name in names):
        return None
    whole, per_pixel, live = (times[name] for name in names)
    ratio = statistics.median(w / (p + b) for w, p, b in zip(whole, per_pixel, live))
    return {"whole_look_ms": statistics.median(whole), "per_pixel_ms": statistics.median(per_pixel),
            "live_ms": statistics.median(live), "whole_over_parts": ratio}
