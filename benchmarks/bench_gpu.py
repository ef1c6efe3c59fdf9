"""The GPU path measured: a look, its stages, a LUT, ACES 2.0, training and augmentation on CUDA, against the copy floor.

    python -m benchmarks gpu [--out DIR] [--budget SECONDS] [--sections a,b,...]

Needs CUDA (the CPU section runs anywhere). Times are medians of CUDA-event timings after warm-up; the things a row
compares alternate (A B A B). Each frame is 3840x2160 (4K) or 1920x1080 float32, the procedural demo scene.
Sections, each skipped once ``--budget`` seconds have passed (compiles are the slow part):

* ``floor``: one device-to-device copy of the frame, the memory floor every ratio is taken against;
* ``look``: ``export/looks/cinematic.json`` eager at 1080p and 4K, compiled (:func:`torchgrade.compile`: CUDA
  graphs) at 4K;
* ``profile``: kernel launches, synchronising calls, value reads and host-to-device copies of one 4K frame;
* ``lut``: a 33³ LUT of the look at 4K, eager and compiled;
* ``augment``: ``RandomPostFX`` against kornia's ``ColorJiggle`` on 256x3x224x224, eager, and its forward+backward;
* ``training``: the look's forward and backward on 16x3x512x512, eager;
* ``stages``: grade, ACES and ACES 2.0 tone maps, scattering bloom, exposure at 4K, eager (compiled for three);
* ``kernels``: the device time of the kernels of a 4K frame of the look, five stages and the LUT, eager, and of
  ``RandomPostFX`` eager and compiled, and the longest kernels of each (what eager time they leave is the GPU waiting
  for launches); ``profile`` records the compiled look's too;
* ``forms``: a 3x3 colour matrix on a 4K frame three ways (the library's broadcast multiply-adds, a channel at a time
  with numbers, a 1x1 convolution), for the choice of the eager form;
* ``cpu``: the look and the LUT on the host's cores, all of them against 2, and the LUT against OpenColorIO;
* ``augment_compiled``: both augmentations compiled (kornia's takes over a minute to compile);
* ``training_compiled``: the look's forward and backward through :func:`torchgrade.compile` against eager;

Writes ``gpu.json`` and ``gpu.md`` to ``--out`` (default ``benchmarks/out``; the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
import traceback
from pathlib import Path

import torch


import torchgrade as tg
from benchmarks.bench_cpu_paths import training_step
from benchmarks.common import ROOT, argument_parser, ocio_processor, packed_rgb, write_results

CINEMATIC = json.loads((ROOT / "export" / "looks" / "cinematic.json").read_text())
SIZES = {"1080p": (1080, 1920), "4K": (2160, 3840)}
ROWS: list = []


def cinematic() -> tg.PostFX:
    return tg.PostFX.from_config(CINEMATIC).eval()


def scene(size: str, device) -> torch.Tensor:
    return tg.scene.demo_scene(*SIZES[size]).to(device).contiguous()


def record(section: str, case: str, **values) -> None:
    row = {"section": section, "case": case, **{k: round(v, 4) if isinstance(v, float) else v for k, v in values.items()}}
    ROWS.append(row)
    print(json.dumps(row), flush=True)


def cuda_ms(calls: dict, runs: int = 20, warmup: int = 3) -> dict:
    """Median ms of each call by CUDA events, the calls alternating (A B A B)."""
    times = {name: [] for name in calls}
    for attempt in range(warmup + runs):
        for name, call in calls.items():
            start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
            start.record()
            call()
            end.record()
            end.synchronize()
            if attempt >= warmup:
                times[name].append(start.elapsed_time(end))
    return {name: statistics.median(values) for name, values in times.items()}


def host_ms(calls: dict, runs: int = 7, warmup: int = 1) -> dict:
    times = {name: [] for name in calls}
    for attempt in range(warmup + runs):
        for name, call in calls.items():
            start = time.perf_counter()
            call()
            if attempt >= warmup:
                times[name].append((time.perf_counter() - start) * 1e3)
    return {name: statistics.median(values) for name, values in times.items()}


def first_call_s(call) -> float:
    """Seconds ``call()`` takes, to the end of its device work: the compile, when it is a compiled call's first."""
    start = time.perf_counter()
    call()
    torch.cuda.synchronize()
    return time.perf_counter() - start


def compiled(module, *example, **kwargs):
    """``tg.compile(module)`` called once on ``example`` (the compile), and the seconds that took."""
    fast = tg.compile(module, **kwargs)
    return fast, first_call_s(lambda: fast(*example))


def floor_ms(image: torch.Tensor) -> float:
    out = torch.empty_like(image)
    return cuda_ms({"copy": lambda: out.copy_(image)}, runs=50)["copy"]


# ---------------------------------------------------------------- sections


def section_floor(device):
    for size in SIZES:
        record("floor", f"copy of a {size} frame", ms=floor_ms(scene(size, device)))


def section_look(device):
    look = cinematic().to(device)
    for size in SIZES:
        image = scene(size, device)
        floor = floor_ms(image)
        with torch.no_grad():
            calls = {"eager": lambda image=image: look(image)}
            if size == "4K":  # one compile: each frame size compiles on its own
                fast, seconds = compiled(look, image)
                calls["compiled"] = lambda fast=fast, image=image: fast(image)
            times = cuda_ms(calls)
        record("look", f"cinematic {size} eager, no_grad", ms=times["eager"], x_floor=times["eager"] / floor)
        if "compiled" in times:
            record("look", f"cinematic {size} compiled (CUDA graphs)", ms=times["compiled"], x_floor=times["compiled"] / floor,
                   compile_s=seconds, max_abs_vs_eager=(fast(image) - look(image)).abs().max().item())


STAGES = {
    "grade": lambda: tg.ColorGrade(**CINEMATIC["grade"]),
    "tonemap aces": lambda: tg.ToneMap("aces"),
    "tonemap aces2": lambda: tg.ToneMap("aces2"),
    "bloom scattering": lambda: tg.Bloom(**CINEMATIC["bloom"]),
    "exposure": lambda: tg.AutoExposure(**CINEMATIC["exposure"]),
}
COMPILED_STAGES = ("tonemap aces", "tonemap aces2", "grade")


def section_stages(device):
    image = scene("4K", device)
    floor = floor_ms(image)
    with torch.no_grad():
        for name, make in STAGES.items():
            stage = make().to(device)
            calls = {"eager": lambda stage=stage: stage(image)}
            seconds = None
            if name in COMPILED_STAGES:
                fast, seconds = compiled(stage, image)
                calls["compiled"] = lambda fast=fast, image=image: fast(image)
            times = cuda_ms(calls)
            for way, ms in times.items():
                extra = {"compile_s": seconds} if way == "compiled" else {}
                record("stages", f"{name} 4K {way}", ms=ms, x_floor=ms / floor, **extra)


def section_lut(device):
    lut = cinematic().to_lut(33).lut.to(device)
    image = scene("4K", device)
    with torch.no_grad():
        exposed = cinematic().to(device).per_pixel_input(image)
    floor = floor_ms(image)
    with torch.no_grad():
        fast, seconds = compiled(lut, exposed)
        times = cuda_ms({"eager": lambda: lut(exposed), "compiled": lambda: fast(exposed)})
    for way, ms in times.items():
        record("lut", f"LUT 33^3 tetrahedral 4K {way}", ms=ms, x_floor=ms / floor, **({"compile_s": seconds} if way == "compiled" else {}))


def section_training(device):
    batch = torch.rand(16, 3, 512, 512, device=device) * 4
    step = training_step(cinematic().to(device), batch)
    record("training", "cinematic forward+backward 16x3x512x512 eager", ms=cuda_ms({"step": step}, runs=10)["step"])


def section_training_compiled(device):
    """The look's forward and backward through ``tg.compile`` (CUDA graphs of both), against eager, alternating."""
    look = cinematic().to(device)
    batch = torch.rand(16, 3, 512, 512, device=device) * 4
    fast = training_step(tg.compile(look, dynamic=False), batch)  # fixed sizes: the look section compiled PostFX at others
    compile_s = first_call_s(fast)  # compiles the forward, then the backward
    times = cuda_ms({"eager": training_step(look, batch), "compiled": fast}, runs=10)
    record("training", "cinematic forward+backward 16x3x512x512 compiled (CUDA graphs)", ms=times["compiled"],
           eager_ms=times["eager"], ratio_to_eager=times["compiled"] / times["eager"], compile_s=compile_s)


def augmentations():
    """``RandomPostFX`` with controls like ``ColorJiggle``'s, and ``ColorJiggle``, on a 256x3x224x224 sRGB batch."""
    import kornia

    ours = tg.RandomPostFX(contrast=30, saturation=30, hue_shift=20, post_exposure=0.5, input_space="srgb")
    jiggle = kornia.augmentation.ColorJiggle(brightness=0.2, contrast=0.3, saturation=0.3, hue=0.05, p=1.0)
    return ours, jiggle


def section_augment(device):
    batch = torch.rand(256, 3, 224, 224, device=device)
    ours, jiggle = augmentations()
    with torch.no_grad():
        eager = cuda_ms({"RandomPostFX": lambda: ours(batch), "ColorJiggle": lambda: jiggle(batch)})
        record("augment", "RandomPostFX vs ColorJiggle eager 256x3x224x224", ms=eager["RandomPostFX"], kornia_ms=eager["ColorJiggle"],
               ratio=eager["RandomPostFX"] / eager["ColorJiggle"])
    step = training_step(ours, batch)
    record("augment", "RandomPostFX forward+backward 256x3x224x224", ms=cuda_ms({"step": step}, runs=10)["step"])


def section_augment_compiled(device):
    batch = torch.rand(256, 3, 224, 224, device=device)
    ours, jiggle = augmentations()
    with torch.no_grad():
        fast_ours, ours_s = compiled(ours, batch)
        fast_jiggle = torch.compile(jiggle)
        jiggle_s = first_call_s(lambda: fast_jiggle(batch))
        both = cuda_ms({"RandomPostFX": lambda: fast_ours(batch), "ColorJiggle": lambda: fast_jiggle(batch)})
        record("augment", "RandomPostFX vs ColorJiggle both compiled", ms=both["RandomPostFX"], kornia_ms=both["ColorJiggle"],
               ratio=both["RandomPostFX"] / both["ColorJiggle"], compile_s=ours_s, kornia_compile_s=jiggle_s)


def profile_counts(call) -> dict:
    from torch.profiler import ProfilerActivity, profile

    call()
    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as recorded:
        call()
        torch.cuda.synchronize()
    events = recorded.key_averages()

    def count(*keys):
        return sum(e.count for e in events if e.key in keys)

    return {
        "launches": count("cudaLaunchKernel", "cuLaunchKernel", "cudaLaunchKernelExC", "cuLaunchKernelEx", "cudaGraphLaunch"),
        "syncs": count("cudaStreamSynchronize", "cudaDeviceSynchronize", "cudaEventSynchronize") - 1,  # less the profile's own
        "value_reads": count("aten::item", "aten::_local_scalar_dense"),
        "host_to_device": sum(e.count for e in events if "HtoD" in e.key),
        "copies": count("cudaMemcpyAsync", "cudaMemcpy"),
    }


def kernel_times(call, top: int = 6) -> tuple:
    """The device time of one call's kernels, in ms, their count, and the ``top`` kernels by device time: (name, count, ms)."""
    from torch.profiler import ProfilerActivity, profile

    call()
    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CUDA]) as recorded:
        call()
        torch.cuda.synchronize()
    kernels = [e for e in recorded.key_averages() if e.device_type == torch.autograd.DeviceType.CUDA]
    ms = {e.key: e.self_device_time_total / 1000 for e in kernels}
    ranked = sorted(kernels, key=lambda e: -ms[e.key])[:top]
    return sum(ms.values()), sum(e.count for e in kernels), [(e.key, e.count, ms[e.key]) for e in ranked]


KERNEL_CASES = ("tonemap aces2", "exposure", "grade", "tonemap aces", "bloom scattering")


def record_kernels(case: str, call) -> None:
    """One row of ``call``'s kernel time and count, and one for each of its longest kernels."""
    total, count, ranked = kernel_times(call)
    record("kernels", f"{case}: all kernels", kernels=count, kernel_ms=total)
    for kernel, times, ms in ranked:
        record("kernels", f"{case}: {kernel[:90]}", count=times, ms=ms)


def section_kernels(device):
    """Where the device time goes: each case's kernel time (the rest of its eager time the GPU waits for launches)
    and its longest kernels; 4K frames of the look, five stages and its 33³ LUT, and ``RandomPostFX`` eager and
    compiled on its batch."""
    image = scene("4K", device)
    cases = {name: STAGES[name]().to(device) for name in KERNEL_CASES}
    cases["cinematic"] = cinematic().to(device)
    cases["LUT 33^3 tetrahedral"] = cinematic().to_lut(33).lut.to(device)
    ours, _ = augmentations()
    ours = ours.to(device)
    batch = torch.rand(256, 3, 224, 224, device=device)
    with torch.no_grad():
        for name, module in cases.items():
            record_kernels(f"{name} 4K eager", lambda module=module: module(image))
        record_kernels("RandomPostFX 256x3x224x224 eager", lambda: ours(batch))
        fast, _ = compiled(ours, batch)
        record_kernels("RandomPostFX 256x3x224x224 compiled", lambda: fast(batch))


def _matrix_by_channel(values, planes) -> torch.Tensor:
    """A 3x3 matrix of numbers on three planes one output channel at a time: a product and two sums by numbers each,
    every operand a whole plane (nine launches, all vectorised)."""
    out = torch.empty(planes[0].shape[:-3] + (3,) + planes[0].shape[-2:], device=planes[0].device)
    for row, channel in zip(values, out.split(1, dim=-3)):
        torch.mul(planes[0], row[0], out=channel).add_(planes[1], alpha=row[1]).add_(planes[2], alpha=row[2])
    return out


def _matrix_as_convolution(matrix: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    """A 3x3 matrix as one 1x1 convolution, cuDNN's TF32 off (it would round the products)."""
    with torch.backends.cudnn.flags(enabled=True, allow_tf32=False):
        return torch.nn.functional.conv2d(image, matrix.reshape(3, 3, 1, 1))


def section_forms(device):
    """Ways to apply a 3x3 colour matrix to a 4K frame, side by side: the library's (``matrix_on_planes``: a product
    and two multiply-adds whose coefficient columns broadcast, three launches in CUDA's unvectorised loop), one output
    channel at a time with numbers (nine vectorised launches), and one 1x1 convolution."""
    from torchgrade.base.planes import matrix_on_planes
    from torchgrade.color.spaces import MATRIX_VALUES

    values = MATRIX_VALUES["srgb_to_ap1"]
    matrix = torch.tensor(values, device=device)
    image = scene("4K", device)
    planes = image.split(1, dim=-3)
    floor = floor_ms(image)
    with torch.no_grad():
        expected = matrix_on_planes(matrix, planes)
        forms = {"broadcast columns (the library's)": lambda: matrix_on_planes(matrix, planes),
                 "a channel at a time, numbers": lambda: _matrix_by_channel(values, planes),
                 "1x1 convolution, no TF32": lambda: _matrix_as_convolution(matrix, image)}
        times = cuda_ms(forms)
        for name, call in forms.items():
            record("forms", f"3x3 matrix 4K: {name}", ms=times[name], x_floor=times[name] / floor,
                   max_abs=(call() - expected).abs().max().item())


def section_profile(device):
    look = cinematic().to(device)
    image = scene("4K", device)
    with torch.no_grad():
        record("profile", "cinematic 4K eager, no_grad", **profile_counts(lambda: look(image)))
        fast, _ = compiled(look, image)
        record("profile", "cinematic 4K compiled (CUDA graphs)", **profile_counts(lambda: fast(image)))
        record_kernels("cinematic 4K compiled", lambda: fast(image))
    batch = torch.rand(16, 3, 512, 512, device=device) * 4
    record("profile", "cinematic forward+backward 16x3x512x512", **profile_counts(training_step(look, batch)))


def section_cpu(device):
    import PyOpenColorIO  # noqa: F401  (OpenColorIO's processor below)

    cores = os.cpu_count()
    image = scene("1080p", "cpu")
    look = cinematic()
    lut = tg.bake_lut(tg.PostFX(grade={"contrast": 20, "saturation": 10}, tonemap="aces"), size=33, shaper="linear",
                      report_tolerance=float("inf"))
    lut.table = lut.table.float()
    pixels = torch.rand(1, 3, 1080, 1920, generator=torch.Generator().manual_seed(0)) * 1.1 - 0.05
    threads_before = torch.get_num_threads()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "look.cube"
        tg.io.write_cube(path, lut)
        processor = ocio_processor(path, "tetrahedral")
        buffer = packed_rgb(pixels)
        results = {}
        try:
            for threads in sorted({2, cores}):  # 2 first: the worker threads a larger count starts stay alive
                torch.set_num_threads(threads)
                with torch.no_grad():
                    times = host_ms({"look": lambda: look(image), "lut": lambda: lut(pixels, "tetrahedral"),
                                     "ocio": lambda: processor.applyRGB(buffer.copy())})
                results[threads] = times
                record("cpu", f"{threads} threads, 1920x1080", look_ms=times["look"], lut_ms=times["lut"], ocio_ms=times["ocio"],
                       lut_vs_ocio=times["lut"] / times["ocio"])
        finally:
            torch.set_num_threads(threads_before)
    if cores > 2:
        record("cpu", f"{cores} threads against 2", look_speedup=results[2]["look"] / results[cores]["look"],
               lut_speedup=results[2]["lut"] / results[cores]["lut"])


SECTIONS = {"floor": section_floor, "look": section_look, "profile": section_profile, "lut": section_lut,
            "augment": section_augment, "training": section_training, "stages": section_stages, "kernels": section_kernels,
            "forms": section_forms, "cpu": section_cpu, "augment_compiled": section_augment_compiled,
            "training_compiled": section_training_compiled}
NEEDS_CUDA = set(SECTIONS) - {"cpu"}


def markdown(info: dict) -> list:
    lines = [f"# The GPU path: {info['device']}", "",
             f"torch {info['torch']}, {info['cpus']} CPU cores; `{info['command']}` ({info['date']}). Medians of CUDA-event "
             "timings after warm-up, the compared calls alternating; x floor = time / one device-to-device copy of the frame.",
             "", "| section | case | values |", "| --- | --- | --- |"]
    for row in ROWS:
        values = ", ".join(f"{k} {v}" for k, v in row.items() if k not in ("section", "case"))
        lines.append(f"| {row['section']} | {row['case']} | {values} |")
    return lines


def main(argv=None) -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--budget", type=float, default=420.0, help="seconds after which the remaining sections are skipped")
    parser.add_argument("--sections", default=",".join(SECTIONS), help=f"comma-separated, of {', '.join(SECTIONS)}")
    args = parser.parse_args(argv)
    chosen = [name.strip() for name in args.sections.split(",") if name.strip()]
    unknown = sorted(set(chosen) - set(SECTIONS))
    if unknown:
        parser.error(f"unknown sections {unknown}")
    cuda = torch.cuda.is_available()
    device = torch.device("cuda" if cuda else "cpu")
    if cuda:
        torch.backends.cuda.matmul.allow_tf32 = False
    info = {"device": torch.cuda.get_device_name() if cuda else "CPU only", "torch": torch.__version__, "cpus": os.cpu_count(),
            "command": "python -m benchmarks gpu " + " ".join(argv if argv is not None else sys.argv[1:]),
            "date": time.strftime("%Y-%m-%d")}
    started, errors, skipped = time.monotonic(), [], []

    def save(announce: bool) -> None:  # after every section: a run stopped at its time limit keeps what it measured
        report = {"info": info, "rows": ROWS, "errors": errors, "skipped": skipped}
        lines = markdown(info) + ([""] + [f"Skipped: {', '.join(skipped)}."] if skipped else []) + \
            ([""] + [f"Failed: {e['section']}: {e['error']}" for e in errors] if errors else [])
        write_results(args.out, "gpu", report, lines, info["command"], device.type, announce=announce)

    for name in chosen:
        if name in NEEDS_CUDA and not cuda:
            skipped.append(f"{name} (no CUDA)")
            continue
        if time.monotonic() - started > args.budget:
            skipped.append(f"{name} (over the {args.budget:.0f} s budget)")
            continue
        begun = time.monotonic()
        try:
            SECTIONS[name](device)
        except Exception as error:  # a section that fails is reported, the others still run
            errors.append({"section": name, "error": repr(error)[:500], "trace": traceback.format_exc()[-2000:]})
            print(f"!! {name}: {error!r}"[:600], flush=True)
        print(f"-- {name}: {time.monotonic() - begun:.1f} s", flush=True)
        save(announce=False)
    save(announce=True)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
