"""What ``tg.compile`` costs and what it saves: first-call compile time cold, warm and from saved cache artifacts.

Each case runs in fresh processes, three times over:

* **cold**: an empty Inductor cache (``TORCHINDUCTOR_CACHE_DIR`` a new folder), as on a new machine or container;
* **warm**: the cold run's Inductor cache, as a second run on the same machine;
* **artifacts**: an empty Inductor cache, but the cold run's ``tg.io.save_compile_cache`` file loaded first
  (``tg.io.load_compile_cache``), as a container that carries the file.

In each process: the eager call's median time (5 calls after one), the first compiled call (the compile, logged as
``torchgrade.compile`` says), the compiled call's median time, and the calls the compile takes to repay
(``compile / (eager - compiled)``). A training case is a forward and backward of ``output.sum()``.

Writes ``compile.json`` and ``compile.md`` to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``). Takes many minutes on 2 cores: every case compiles three times from scratch.

    .venv/bin/python -m benchmarks compile [--cases NAME ...] [--out DIR]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


from benchmarks.common import ROOT, argument_parser, write_results

COMMAND = ".venv/bin/python -m benchmarks compile --out benchmarks/results"
CASES = {
    "look 1x3x1080x1920": dict(module="look", shape=(1, 3, 1080, 1920), training=False, autocast=None),
    "look training 16x3x128x128": dict(module="look", shape=(16, 3, 128, 128), training=True, autocast=None),
    "look training 16x3x128x128, autocast bfloat16": dict(module="look", shape=(16, 3, 128, 128), training=True,
                                                          autocast="bfloat16"),
    "RandomPostFX 64x3x224x224": dict(module="augment", shape=(64, 3, 224, 224), training=False, autocast=None),
    "RandomPostFX training 16x3x128x128": dict(module="augment", shape=(16, 3, 128, 128), training=True, autocast=None),
}
"""Each case: the module (the shipped look, or ``RandomPostFX`` with ``ColorJiggle``'s controls), the batch, whether
gradients are taken, and the CPU autocast dtype."""

CHILD = r"""
import json, statistics, sys, time
import torch, torchgrade as tg
case, cache, role = json.loads(sys.argv[1]), sys.argv[2], sys.argv[3]
torch.set_num_threads(2)
if role == "artifacts":
    assert tg.io.load_compile_cache(cache)
if case["module"] == "look":
    module = tg.PostFX.from_config("export/looks/cinematic.json").eval()
else:
    module = tg.RandomPostFX(post_exposure=(-0.5, 0.5), contrast=(-20, 20), saturation=(-20, 20), hue_shift=(-36, 36))
image = torch.rand(case["shape"], generator=torch.Generator().manual_seed(0)) * 4
autocast = torch.autocast("cpu", dtype=getattr(torch, case["autocast"])) if case["autocast"] else torch.autocast("cpu", enabled=False)

def call(run):
    x = image.clone().requires_grad_(case["training"])
    with torch.set_grad_enabled(case["training"]), autocast:
        out = run(x)
    if case["training"]:
        out.sum().backward()

def median(run):
    call(run)
    times = []
    for _ in range(5):
        started = time.perf_counter(); call(run); times.append(time.perf_counter() - started)
    return statistics.median(times)

eager = median(module)
compiled = tg.compile(module)
started = time.perf_counter()
call(compiled)
first = time.perf_counter() - started
steady = median(compiled)
if role == "cold":
    tg.io.save_compile_cache(cache)
print(json.dumps({"eager_s": eager, "first_call_s": first, "compiled_s": steady}))
"""


def run_case(name: str, folder: Path) -> dict:
    """The three runs of one case (cold, warm, artifacts), each a fresh process."""
    case = CASES[name]
    inductor, artifacts = folder / "inductor", folder / "look.compiled"
    runs = {}
    for role in ("cold", "warm", "artifacts"):
        cache_dir = inductor if role != "artifacts" else folder / "inductor-empty"
        environment = {**os.environ, "TORCHINDUCTOR_CACHE_DIR": str(cache_dir)}
        started = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", CHILD, json.dumps(case), str(artifacts), role], cwd=ROOT,
                              env=environment, capture_output=True, text=True, timeout=3600)
        if done.returncode != 0:
            raise RuntimeError(f"{name} ({role}) failed:\n{done.stderr[-3000:]}")
        run = json.loads(done.stdout.strip().splitlines()[-1])
        saving = run["eager_s"] - run["compiled_s"]
        run["repaid_after_calls"] = round(run["first_call_s"] / saving) if saving > 0 else None
        run["process_s"] = time.perf_counter() - started
        runs[role] = run
        print(f"{name}, {role}: first call {run['first_call_s']:.1f} s, eager {1e3 * run['eager_s']:.1f} ms, "
              f"compiled {1e3 * run['compiled_s']:.1f} ms", flush=True)
    return runs


def main(argv=None) -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES), metavar="NAME")
    args = parser.parse_args(argv)
    report = {}
    for name in args.cases:
        with tempfile.TemporaryDirectory() as folder:
            report[name] = run_case(name, Path(folder))
    write_results(args.out, "compile", report, render(report), COMMAND)


def render(report: dict) -> list:
    """The results table: first calls by cache, the median eager and compiled call over the three processes, and the
    calls the cold compile takes to repay at those medians."""
    lines = ["# What tg.compile costs and saves (CPU)", "",
             f"`{COMMAND}`: fresh processes, 2 threads. First call: the compile (and the call), with an empty Inductor "
             "cache (cold), the cold run's cache (warm), or an empty one and the cold run's saved cache artifacts; "
             "then the median of the eager and the compiled call over the three processes; calls to repay: the cold "
             "first call over what a compiled call saves.", "",
             "| case | cold first call | warm first call | from artifacts | eager ms | compiled ms | calls to repay (cold) |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, runs in report.items():
        eager, compiled = (statistics.median(run[key] for run in runs.values()) for key in ("eager_s", "compiled_s"))
        saving = eager - compiled
        repaid = f"{round(runs['cold']['first_call_s'] / saving):,}" if saving > 0 else "never (not faster)"
        lines.append(f"| {name} | {runs['cold']['first_call_s']:.1f} s | {runs['warm']['first_call_s']:.1f} s | "
                     f"{runs['artifacts']['first_call_s']:.1f} s | {1e3 * eager:.1f} | {1e3 * compiled:.1f} | {repaid} |")
    return lines




if __name__ == "__main__":
    main()
