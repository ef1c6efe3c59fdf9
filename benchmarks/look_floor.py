"""The whole look against the CPU's floor: the shipped cinematic look (``export/looks/cinematic.json``) and its stages
on a 1920x1080 float32 frame, eager, through ``tg.compile`` and exported to onnxruntime, each timed in the same rounds
as a plain copy of the frame.

    .venv/bin/python -m benchmarks look_floor [--quick] [--counts] [--threads N] [--rounds N] [--out DIR]

**Timed** (:func:`benchmarks.common.interleaved_ms`: every round runs each case once, the order turning round to
round, after a warm-up round): a plain frame copy (``clone``, the baseline), a copy into a frame allocated once, the
eager look, the compiled look (``tg.compile``, after its cold compile, which is timed apart with Inductor's cache in an
empty folder), eye adaptation (histogram metering, centre mask: every frame meters afresh), bloom (scattering), the
grade and the ACES tone map each on the frame it gets in the look, and onnxruntime running the exported look
(``tg.onnx.export``'s defaults, on ``--threads`` intra-op threads). Reported: the median ms and the median over rounds
of each case's time over the copy's in the same round (a load change between rounds cancels), and onnxruntime's over
the eager look's.

**Counted** (deterministic: ``--counts`` records only these, the columns that may be committed from a busy machine,
and no time, the compile's included):

* eager, a second frame of the look and of each stage on the ``meta`` device (shapes, nothing computed: each formula's one form on
  whole frames, where the CPU runs per-pixel stages in strips of rows) at the frame's size, under
  :class:`~torchgrade.testing.dispatch.DispatchCount`: the operations dispatched, those whose result holds a plane of
  the frame or more, and the bytes those results hold in frames (full-frame passes and temporaries, each written to
  memory and read back);
* compiled, read from the code Inductor generated for the timed graph (captured from the ``output_code`` log that
  ``torch._logging.set_logs`` turns on): its kernels, their loop nests, and the buffers of a plane or more it allocates
  (the output among them) and what they hold in frames, sizes evaluated at the frame's;
* exported: the nodes of the file (a ``Scan``'s body included, and the main graph's alone) and their operators;
* metering: how far counting the histogram a value a block (``histogram_block``, :data:`METERING_BLOCKS`), or every
  pixel of the frame box-filtered 2x2, moves the metered exposure from counting every pixel, in stops, on the five
  sample photographs at their full sizes, each metering mask.

``--quick`` (for the tests): a 180x320 frame, 3 rounds, no ``tg.compile``. The results carry the commit, the command,
the threads and the device. Writes look_floor.json and look_floor.md to ``--out`` (default benchmarks/out; the
committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import ast
import collections
import contextlib
import copy
import logging
import math
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import onnx
import torch

import torchgrade as tg
from benchmarks.common import ROOT, argument_parser, interleaved_ms, mark_table, median_ratio, sample_exr, write_results
from benchmarks.suite.stamp import source_commit
from torchgrade.onnx.verify import graph_nodes
from torchgrade.testing.dispatch import DispatchCount

COMMAND = ".venv/bin/python -m benchmarks look_floor"
QUICK = "a 180x320 frame, 3 rounds, no tg.compile"
LOOK = ROOT / "export" / "looks" / "cinematic.json"
FRAME, QUICK_FRAME = (1080, 1920), (180, 320)
ROUNDS, QUICK_ROUNDS = 15, 3
THREADS = 2
COPY, EAGER, COMPILED, EXPORTED = "frame copy", "eager whole look", "compiled whole look", "onnxruntime, exported look"
STAGES = {"exposure": "exposure stage (histogram, centre mask)", "bloom": "bloom stage (scattering)", "grade": "grade",
          "tonemap": "ACES tone map"}
"""The look's stages timed alone, by slot, each on the frame it gets in the look."""
PHOTOGRAPHS = ("Desk", "CandleGlass", "GoldenGate", "Garden", "Carrots")
TARGETS = {EAGER: 60.0, COMPILED: 20.0, STAGES["exposure"]: 5.0, STAGES["bloom"]: 10.0}
"""What each case should cost at most, in frame copies timed in the same rounds (onnxruntime: :data:`EXPORTED_TARGET`
eager looks; the cold compile: :data:`COLD_COMPILE_TARGET`); the table says whether a run met each."""
EXPORTED_TARGET, COLD_COMPILE_TARGET = 1.0, 30.0
METERING_BLOCKS = (2, 4)
"""The histogram's blocks whose effect on the metering is measured: 2x2 (a quarter of the values), and 4x4."""


def stage_inputs(look: tg.PostFX, scene: torch.Tensor) -> dict:
    """The frame each stage of ``look`` gets in it, by slot, the first the scene."""
    frames, image = {}, scene
    with torch.no_grad():
        for name, stage in look.stages().items():
            frames[name] = image
            image = stage(image)
    return frames


def eager_calls(look: tg.PostFX, scene: torch.Tensor) -> dict:
    """The eager cases, by row name: the copies, the whole look and each stage on its own frame."""
    into = torch.empty_like(scene)
    frames = stage_inputs(look, scene)
    calls = {COPY: scene.clone, "frame copy into a frame made once": lambda: into.copy_(scene), EAGER: lambda: look(scene)}
    calls.update({STAGES[name]: (lambda stage=stage, frame=frames[name]: stage(frame)) for name, stage in look.stages().items()})
    return calls


# ---------------------------------------------------------------- Inductor's code


@contextlib.contextmanager
def inductor_output_code():
    """Within the block, every source Inductor generates is appended to the list it yields: the ``output_code`` log
    (``torch._logging.set_logs``), taken from the ``torch._inductor`` logger by a handler of ours instead of torch's
    on stderr. After the block torch's logging is at its defaults, the logger's handlers those it had."""
    sources = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            message = record.getMessage()
            if message.startswith("Output code:"):
                sources.append(message)

    logger = logging.getLogger("torch._inductor")
    kept = list(logger.handlers)
    torch._logging.set_logs(output_code=True)
    logger.handlers = [Collect()]
    try:
        yield sources
    finally:
        torch._logging.set_logs()  # torch's defaults, then the handlers the logger had
        logger.handlers = kept


KERNEL = re.compile(r"^(cpp_fused_\w+) = async_compile", re.MULTILINE)
LOOP_NEST = re.compile(r"for\(int64_t x0=")
BUFFER = re.compile(r"empty_strided_cpu\(\(([^()]*(?:\([^()]*\)[^()]*)*)\),")
SIZE = re.compile(r"^\s+(s\d+) = (arg\d+_1)$", re.MULTILINE)
EXAMPLE = re.compile(r"^\s+(arg\d+_1) = (\d+)$", re.MULTILINE)


def evaluated(expression: str, sizes: dict):
    """An integer size expression of Inductor's wrapper code (``3*s0``, ``(1 + s1)//2``) at ``sizes``; ``None`` for
    anything else.

    Examples:
        >>> evaluated("(1 + s1)//2", {"s1": 1080}), evaluated("f(s1)", {"s1": 1})
        (540, None)
    """
    operators = {ast.Add: int.__add__, ast.Sub: int.__sub__, ast.Mult: int.__mul__, ast.FloorDiv: int.__floordiv__}

    def value(node):
        if isinstance(node, ast.Constant) and isinstance(node.value, int):
            return node.value
        if isinstance(node, ast.Name) and node.id in sizes:
            return sizes[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in operators:
            return operators[type(node.op)](value(node.left), value(node.right))
        raise ValueError(ast.dump(node))

    try:
        return value(ast.parse(expression, mode="eval").body)
    except (SyntaxError, ValueError):
        return None


def code_counts(source: str, plane: int) -> dict:
    """One generated graph's kernels, loop nests and buffers of at least ``plane`` elements (with what they hold, in
    frames of 3 planes), its symbolic sizes taken at the example it was compiled for (its ``get_args``)."""
    example = dict(EXAMPLE.findall(source))
    sizes = {symbol: int(example[argument]) for symbol, argument in SIZE.findall(source) if argument in example}
    elements = []
    for shape in BUFFER.findall(source):
        dimensions = [evaluated(d.strip(), sizes) for d in shape.split(",") if d.strip()]
        if None not in dimensions:
            elements.append(torch.Size(dimensions).numel())
    large = [n for n in elements if n >= plane]
    return {"kernels": len(KERNEL.findall(source)), "loop_nests": len(LOOP_NEST.findall(source)),
            "frame_buffers": len(large), "frames_written": round(sum(large) / (3 * plane), 2)}


def compiled_look(look: tg.PostFX, scene: torch.Tensor) -> tuple:
    """``tg.compile`` of ``look``, compiled cold on ``scene`` (Inductor's cache in an empty folder): the compiled
    module, the compile's seconds and the counts of its generated code (:func:`code_counts`, summed over graphs)."""
    compiled = tg.compile(look, verbose=False)
    plane = scene.shape[-2] * scene.shape[-1]
    with tempfile.TemporaryDirectory(prefix="torchgrade-inductor-") as cache, inductor_output_code() as sources:
        kept = os.environ.get("TORCHINDUCTOR_CACHE_DIR")
        os.environ["TORCHINDUCTOR_CACHE_DIR"] = cache
        try:
            started = time.perf_counter()
            with torch.no_grad():
                compiled(scene)
            seconds = time.perf_counter() - started
        finally:
            if kept is None:
                del os.environ["TORCHINDUCTOR_CACHE_DIR"]
            else:
                os.environ["TORCHINDUCTOR_CACHE_DIR"] = kept
    per_graph = [code_counts(source, plane) for source in sources]
    counts = {key: round(sum(c[key] for c in per_graph), 2) for key in ("kernels", "loop_nests", "frame_buffers", "frames_written")}
    return compiled, round(seconds, 1), {"graphs": len(per_graph), **counts}


# ---------------------------------------------------------------- the exported look


def exported_look(look: tg.PostFX, scene: torch.Tensor, folder: Path, threads: int) -> tuple:
    """The look exported with ``tg.onnx.export``'s defaults into ``folder``: a call of onnxruntime on ``scene`` (on
    ``threads`` intra-op threads) and the file's nodes (:func:`node_counts`)."""
    path = tg.onnx.export(look, folder / "cinematic.onnx")
    runner = tg.onnx.session(path, threads=threads)
    named = tg.onnx.feeds(runner, look, scene)
    return (lambda: runner.run(None, named)), node_counts(onnx.load(str(path)))


def node_counts(model: onnx.ModelProto) -> dict:
    """The nodes of ``model``, a ``Scan``'s body included, of its main graph alone, and by operator (most first)."""
    nodes = graph_nodes(model.graph)
    operators = collections.Counter(node.op_type for node in nodes)
    return {"nodes": len(nodes), "main_graph_nodes": len(model.graph.node), "operators": dict(operators.most_common())}


# ---------------------------------------------------------------- eager counts and timing


def eager_counts(look: tg.PostFX, shape: torch.Size) -> dict:
    """A second frame of the look and of each of its stages on the ``meta`` device, of ``shape``, under
    :class:`~torchgrade.testing.dispatch.DispatchCount`: the operations dispatched, those whose result holds a plane of
    the frame or more, and those results' bytes in frames."""
    look = copy.deepcopy(look).to("meta")
    frame = torch.empty(shape, device="meta")
    calls = {EAGER: look, **{STAGES[name]: stage for name, stage in look.stages().items()}}
    counts = {}
    for name, call in calls.items():
        for _ in range(2):  # the first frame makes the constants later frames reuse (under the mode, as they are used)
            with torch.no_grad(), DispatchCount(frame=frame) as counted:
                call(frame)
        counts[name] = {"operations": counted.launches, "frame_results": sum(counted.frame_writes.values()),
                        "frames_written": round(counted.frames_written, 2)}
    return counts


def timed(calls: dict, rounds: int) -> dict:
    """Median ms of each call and the median over rounds of its time over the copy's, interleaved; onnxruntime's over
    the eager look's too."""
    times = interleaved_ms(calls, rounds)
    rows = {name: {"ms": round(statistics.median(ms), 2), "over_copy": round(median_ratio(times, name, COPY), 1)}
            for name, ms in times.items()}
    if EXPORTED in rows:
        rows[EXPORTED]["over_eager"] = round(median_ratio(times, EXPORTED, EAGER), 2)
    return {"rows": rows, "rounds_ms": {name: [round(ms, 2) for ms in values] for name, values in times.items()}}


def metering_ways(image: torch.Tensor) -> dict:
    """The ways of metering ``image`` that :func:`metering_effect` compares with counting every pixel, by name: a value a
    block (each of :data:`METERING_BLOCKS`), and every pixel of the frame box-filtered to half its sides (the mean of
    each 2x2 block's light, where the blocks take the mean of its stops)."""
    box = torch.nn.functional.avg_pool2d(image, 2, ceil_mode=True)
    ways = {f"{block}x{block} blocks": (lambda mask, block=block: tg.exposure.meter_luminance(image, "histogram", mask=mask, block=block))
            for block in METERING_BLOCKS}
    ways["the frame box-filtered 2x2"] = lambda mask: tg.exposure.meter_luminance(box, "histogram", mask=mask, block=1)
    return ways


def metering_effect() -> dict:
    """``{photograph: {mask: {way: stops}}}``: how far each of :func:`metering_ways` moves histogram metering from
    counting every pixel, on each sample photograph at its full size."""
    effect = {}
    for name in PHOTOGRAPHS:
        image, effect[name] = sample_exr(name, to_rec709=True), {}
        for mask in tg.exposure.METERING_MASKS:
            every = float(tg.exposure.meter_luminance(image, "histogram", mask=mask, block=1))
            effect[name][mask] = {way: round(abs(math.log2(float(meter(mask)) / every)), 4) for way, meter in metering_ways(image).items()}
    return effect


# ---------------------------------------------------------------- report


def _against(value: float, target, unit: str = "") -> str:
    return "" if target is None else f"≤ {target:g}{unit}{'' if value <= target else ': missed'}"


def time_table(report: dict) -> list:
    """The timed cases: ms, frame copies and the target of each (:data:`TARGETS`; onnxruntime's in eager looks)."""
    rows = report["timing"]["rows"]
    lines = ["| case | ms | × frame copy | × eager look | target |", "| --- | ---: | ---: | ---: | --- |"]
    for name, row in rows.items():
        if "over_eager" in row:
            lines.append(f"| {name} | {row['ms']} | {row['over_copy']} | {row['over_eager']} | "
                         f"{_against(row['over_eager'], EXPORTED_TARGET, ' eager look')} |")
        else:
            lines.append(f"| {name} | {row['ms']} | {row['over_copy']} |  | {_against(row['over_copy'], TARGETS.get(name), ' copies')} |")
    return lines


def markdown(report: dict) -> list:
    """The report as markdown lines."""
    height, width = report["frame"]
    lines = ["# The whole look against the CPU's floor", "",
             f"`{report['command']}` at `{report['commit']}`{' (modified)' if report['modified'] else ''}: the cinematic "
             f"look on a {width}x{height} float32 frame, {report['threads']} torch threads, {report['device']}.", ""]
    if report.get("timing"):
        lines += [f"## Time (medians of {report['rounds']} interleaved rounds; ratios: median of each round's ratio)", "",
                  *mark_table("floor", "time", time_table(report))]
        if report.get("cold_compile_s") is not None:
            lines += ["", f"Cold compile of the look (an empty Inductor cache): {report['cold_compile_s']} s (target "
                      f"{_against(report['cold_compile_s'], COLD_COMPILE_TARGET, ' s')})."]
        lines += [""]
    else:
        lines += ["Counts only (`--counts`): the timing columns come from a run without it on a quiet machine.", ""]
    lines += ["## Eager: operations dispatched, and results of a plane or more (`DispatchCount`, the `meta` device)", "",
              "| case | operations | results of a plane or more | frames written |", "| --- | ---: | ---: | ---: |"]
    lines += [f"| {name} | {c['operations']} | {c['frame_results']} | {c['frames_written']} |" for name, c in report["eager_counts"].items()]
    if report.get("inductor"):
        c = report["inductor"]
        lines += ["", "## Compiled: Inductor's generated code for the timed graph", "",
                  "| graphs | kernels | loop nests | buffers of a plane or more | frames written |", "| ---: | ---: | ---: | ---: | ---: |",
                  f"| {c['graphs']} | {c['kernels']} | {c['loop_nests']} | {c['frame_buffers']} | {c['frames_written']} |"]
    ways = next(iter(next(iter(report["metering"].values())).values()))
    lines += ["", "## Metering: histogram metering's distance from counting every pixel, in stops (sample photographs, full size)", "",
              "| photograph, mask | " + " | ".join(ways) + " |", "| --- |" + " ---: |" * len(ways)]
    lines += [f"| {name}, {mask} | " + " | ".join(str(stops) for stops in by_way.values()) + " |"
              for name, masks in report["metering"].items() for mask, by_way in masks.items()]
    nodes = report["onnx"]
    top = ", ".join(f"{count} `{op}`" for op, count in list(nodes["operators"].items())[:12])
    lines += ["", "## Exported", "", f"{nodes['nodes']} nodes ({nodes['main_graph_nodes']} in the main graph, the rest in its "
              f"`Scan`'s body); most used: {top}."]
    return lines


def measure(quick: bool, counts_only: bool, rounds: int, threads: int) -> dict:
    """Every figure of one run (see the module's docstring), on ``threads`` torch threads (the count before is restored)."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return _measured(quick, counts_only, rounds)
    finally:
        torch.set_num_threads(before)


def _measured(quick: bool, counts_only: bool, rounds: int) -> dict:
    threads = torch.get_num_threads()
    look = tg.PostFX.from_config(LOOK).eval()
    scene = tg.scene.demo_scene(*(QUICK_FRAME if quick else FRAME)).contiguous()
    calls = eager_calls(look, scene)
    report = {"frame": list(scene.shape[-2:]), "threads": threads, "device": "cpu", "rounds": rounds,
              "eager_counts": eager_counts(look, scene.shape), "metering": metering_effect(), "cold_compile_s": None, "inductor": None}
    if not quick:
        compiled, seconds, report["inductor"] = compiled_look(look, scene)
        report["cold_compile_s"] = None if counts_only else seconds
        calls[COMPILED] = lambda: compiled(scene)
    with tempfile.TemporaryDirectory(prefix="torchgrade-look-floor-") as folder:
        calls[EXPORTED], report["onnx"] = exported_look(look, scene, Path(folder), threads)
        if not counts_only:
            report["timing"] = timed(calls, rounds)
    return report


def main(argv=None) -> int:
    parser = argument_parser(__doc__, QUICK)
    parser.add_argument("--counts", action="store_true", help="only the deterministic columns (operations, Inductor's code, nodes)")
    parser.add_argument("--threads", type=int, default=THREADS, help=f"torch and onnxruntime threads (default {THREADS})")
    parser.add_argument("--rounds", type=int, default=None, help=f"timed rounds (default {ROUNDS}, {QUICK_ROUNDS} with --quick)")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    command = " ".join([COMMAND, *argv])
    rounds = args.rounds or (QUICK_ROUNDS if args.quick else ROUNDS)
    report = {"command": command, **source_commit(), **measure(args.quick, args.counts, rounds, args.threads)}
    write_results(args.out, "look_floor", report, markdown(report), command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
