"""What a compiled frame would cost a GPU, read from the code Inductor generates for the CPU.

    python -m benchmarks inductor_proxy [--out DIR] [--cases NAME ...]

Each case of ``bench_gpu.py`` that it compiles (the look, its stages, ACES 2.0, ``RandomPostFX``, the look's training
step) is compiled with ``torch.compile(fullgraph=True)`` on a small CPU frame, and the generated code is read
(``run_and_get_code``):

* **loops**: each loop nest Inductor writes (over the frame, or over something small: a 3x3 matrix, a pyramid level) is,
  on CUDA, a Triton kernel of its own (steps with the same number of elements fuse into one loop, and into one kernel;
  a step on the frame's 3 values a pixel after one on a plane's 1 starts another);
* **frames written**: the buffers of a plane's size or more that the graph allocates, in frames (3 planes each): each
  is written by one kernel and read back by a later one, memory traffic that a fused chain keeps in registers. The
  output is one of them. A training step compiles two graphs, the forward and the backward: the forward's frames
  are its output and what it saves for the backward (which reads them back); the backward's, the image's gradient
  and what it writes on the way. It is compiled by ``tg.compile``, which partitions it as PyTorch does.

A count of structure, not a time: the GPU run (``benchmarks/gpu_check.sh``) measures. Compile seconds are the CPU's
(a C++ compiler; Triton's differ) with Inductor's caches off. About 5 minutes on 2 cores, most of it ACES 2.0 and
the training step.
"""

from __future__ import annotations

import re
import time
import warnings

import torch


import torchgrade as tg
from benchmarks.bench_gpu import STAGES, augmentations, cinematic
from benchmarks.common import argument_parser, write_results

FRAME = (1, 3, 64, 96)
CASES = {"cinematic look": cinematic, **{name: STAGES[name] for name in ("grade", "tonemap aces", "tonemap aces2", "bloom scattering", "exposure")},
         "RandomPostFX": lambda: augmentations()[0]}
TRAINING = {"cinematic look, training": cinematic}
"""Cases compiled as ``bench_gpu``'s training step: the look's forward and backward (of the output's mean) on an
image that requires grad."""
LOOP_NEST = re.compile(r"for\(int64_t x0=")
BUFFER = re.compile(r"empty_strided_cpu\(\(([\d, ]+)\)")


def generated_code(module: torch.nn.Module, training: bool = False) -> tuple:
    """Inductor's code for one frame of ``module`` on the CPU, one source a graph, and the seconds it took to compile:
    no_grad through ``torch.compile(fullgraph=True)``; ``training``, its forward and backward through ``tg.compile``."""
    from torch._inductor.utils import run_and_get_code

    torch.compiler.reset()
    image = tg.scene.demo_scene(*FRAME[2:])[None].contiguous().requires_grad_(training)
    if training:
        compiled = tg.compile(module, dynamic=False, verbose=False)
    else:
        compiled = torch.compile(module.eval(), fullgraph=True)

    def step():
        out = compiled(image)
        if training:
            out.mean().backward()

    start = time.perf_counter()
    with torch.set_grad_enabled(training), torch._inductor.config.patch(force_disable_caches=True):
        _, code = run_and_get_code(step)
    return code, time.perf_counter() - start


def structure(source: str) -> dict:
    """Loop nests, and the frames the graph writes (buffers of a plane or more, in frames)."""
    plane = FRAME[2] * FRAME[3]
    sizes = [torch.Size(int(n) for n in shape.replace(" ", "").split(",") if n).numel() for shape in BUFFER.findall(source)]
    written = [size for size in sizes if size >= plane]
    return {"loops": len(LOOP_NEST.findall(source)), "frame_buffers": len(written),
            "frames_written": round(sum(written) / (3 * plane), 2)}


def main(argv=None) -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--cases", nargs="+", choices=[*CASES, *TRAINING], default=[*CASES, *TRAINING])
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")  # the look's baked-LUT accuracy notes
    rows = []
    for name in args.cases:
        training = name in TRAINING
        sources, seconds = generated_code({**CASES, **TRAINING}[name](), training)
        graphs = ("forward", "backward") if training else ("",)
        for graph, source in zip(graphs, sources, strict=True):
            rows.append({"case": f"{name} {graph}".strip(), **structure(source), "compile_s": round(seconds, 1)})
            print(rows[-1], flush=True)
    lines = ["# Compiled frames, read from Inductor's CPU code", "",
             f"torch {torch.__version__}, torchgrade {tg.__version__}, a {FRAME[2]}x{FRAME[3]} frame, one thread. Loops: the "
             "loop nests of the generated code (on CUDA, a kernel each); frames written: the buffers of a plane's size or more, in "
             "frames (each written by one kernel, read back by another; the output among them; in training the forward's "
             "are what it saves for the backward and its output, as PyTorch's partitioner chose). Compile seconds of a training step: its two graphs together. "
             "See `benchmarks/inductor_proxy.py`.", "",
             "| case | loops | buffers | frames written | compile s (CPU) |", "| --- | ---: | ---: | ---: | ---: |"]
    lines += [f"| {r['case']} | {r['loops']} | {r['frame_buffers']} | {r['frames_written']} | {r['compile_s']} |" for r in rows]
    args.out.mkdir(parents=True, exist_ok=True)
    write_results(args.out, "inductor_proxy", {"frame": list(FRAME), "rows": rows},
                  lines, "python -m benchmarks inductor_proxy --out DIR")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
