"""The CPU forms measured against the operations they replace: the figures behind the forms and sizes the maths
modules, the CPU kernels of their operators and the CPU's execution policy choose (:mod:`torchgrade.runtime.policy`).

    .venv/bin/python -m benchmarks cpu_forms [--quick]

Each row times torchgrade's form and the form it replaces on the same input, one after the other in every round
(the order turning round to round, :func:`benchmarks.common.interleaved_ms`), and reports the median over rounds of
the two times' ratio, replaced over torchgrade's (above 1: torchgrade's is faster). The strip and LUT-run tables time
one call at each size against the size the policy takes. The docstrings that choose a form point here by row name.
Writes cpu_forms.json and cpu_forms.md to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import statistics
import sys
from pathlib import Path
from typing import Callable, NamedTuple

import kornia.filters
import torch
import torch.nn.functional as F

import torchgrade as tg
from benchmarks.common import argument_parser, interleaved_ms, median_ratio, write_results
from torchgrade.base.planes import apply_matrix, channel_sum
from torchgrade.bloom.blur import UNITY_BLUR_WEIGHTS, _mirror_filter_by_shifts, mirrored, unity_blur
from torchgrade.bloom.prefilter import cross_sum
from torchgrade.bloom.pyramid import halve
from torchgrade.lut import identity_table, operator
from torchgrade.lut.kernels import KERNELS, tetrahedron
from torchgrade.lut.lattice import planar_table
from torchgrade.match.residual import lattice_coordinates
from torchgrade.runtime import policy, strips
from torchgrade.runtime.checks import warn_if_eight_bit

COMMAND = ".venv/bin/python -m benchmarks cpu_forms"
QUICK = "fewer rounds, and the strip and LUT-run sizes of the policy and its neighbours only"
LEVEL = (1, 3, 540, 960)
"""Bloom's first pyramid level of a 1920x1080 frame."""
STRIP = (1, 3, 68, 1920)
"""A strip of about 2^17 pixels, what a look's per-pixel stages run on at 2 threads."""
FRAME = (1, 3, 1080, 1920)
ROUNDS, QUICK_ROUNDS = 9, 5


class Row(NamedTuple):
    """One comparison: torchgrade's ``ours`` against ``replaced``, both calls of no arguments."""

    name: str
    ours: str
    replaced: str
    calls: tuple


def _cross_kernel() -> torch.Tensor:
    kernel = torch.zeros(1, 3, 3)
    kernel[0, 1, 1] = 1.0
    kernel[0, ::2, ::2] = 1.0
    return kernel


def lookup_matrix(coords: torch.Tensor, size: int) -> torch.Tensor:
    """The tetrahedral lookup at fixed lattice coordinates ``(3, P)`` as a sparse ``(P, size³)`` COO matrix of weights:
    the form a residual fit once took, one sparse product a step."""
    indices, (f_max, f_mid, f_min) = tetrahedron(coords, size)
    rows = torch.arange(coords.shape[1]).repeat(4)
    weights = torch.cat([1.0 - f_max, f_max - f_mid, f_mid - f_min, f_min])
    columns = torch.cat(indices).long()
    return torch.sparse_coo_tensor(torch.stack([rows, columns]), weights, (coords.shape[1], size**3)).coalesce()


def _sparse_backward(matrix: torch.Tensor, table: torch.Tensor) -> Callable[[], None]:
    """A step of a fit through a fixed sparse lookup matrix: the product and its backward to the table."""
    def step():
        with torch.enable_grad():
            (matrix @ table.T).square().sum().backward()
    return step


def _gathered_backward(coords: torch.Tensor, table: torch.Tensor, size: int) -> Callable[[], None]:
    """The same step through the tetrahedral gathers (:data:`torchgrade.lut.kernels.KERNELS`)."""
    def step():
        with torch.enable_grad():
            KERNELS["tetrahedral"](coords, table, size).square().sum().backward()
    return step


def rows() -> list:
    """Every comparison, each on the input its docstring speaks of."""
    generator = torch.Generator().manual_seed(0)
    level = torch.rand(LEVEL, generator=generator) * 4
    strip = torch.rand(STRIP, generator=generator) * 4
    frame = torch.randn(FRAME, generator=generator)
    matrix = torch.rand(3, 3, generator=generator)
    weights = (0.2126, 0.7152, 0.0722)
    weight_tensor = torch.tensor(weights).reshape(3, 1, 1)
    fit_pixels, size = 1 << 16, 17
    display = torch.rand(1, 3, fit_pixels, 1, generator=generator, dtype=torch.float64)
    coords = lattice_coordinates(display, size)
    table = planar_table(identity_table(size, dtype=torch.float64)).requires_grad_()
    return [
        Row("bloom halving, even sides", "four strided views summed", "F.avg_pool2d",
            (lambda: halve(level), lambda: F.avg_pool2d(level, 2))),
        Row("bloom blur, Unity's 9 taps", "sums of shifted views (mirror_filter's CPU kernel)", "kornia filter2d_separable",
            (lambda: _mirror_filter_by_shifts(level, UNITY_BLUR_WEIGHTS), lambda: unity_blur(level, any_size=True))),
        Row("firefly cross sum", "sums of shifted views (cross_sum)", "kornia filter2d, 3x3",
            (lambda: cross_sum(level), lambda: kornia.filters.filter2d(level, _cross_kernel(), border_type="replicate"))),
        Row("mirror padding of rows, radius 4", "edge slices flipped and joined", "a gather (index_select)",
            (lambda: mirrored(level, -1, 4), lambda: mirrored(level, -1, 4, any_size=True))),
        Row("3x3 colour matrix, a strip", "three multiply-adds (apply_matrix)", "torch.einsum",
            (lambda: apply_matrix(matrix, strip), lambda: torch.einsum("ij,...jhw->...ihw", matrix, strip))),
        Row("channel sum by numbers, a strip", "three passes (channel_sum)", "product and channel reduction",
            (lambda: channel_sum(strip, weights), lambda: (strip * weight_tensor).sum(-3, keepdim=True))),
        Row("residual fit: the lookup and its backward", "tetrahedral gathers", "a sparse lookup matrix (COO)",
            (_gathered_backward(coords, table, size), _sparse_backward(lookup_matrix(coords, size), table))),
        Row("8-bit check of a frame", "warn_if_eight_bit", "a copy of the frame",
            (lambda: warn_if_eight_bit(frame), frame.clone)),
    ]


def compare(rows_: list, rounds: int) -> dict:
    """``{row name: {"ours ms", "replaced ms", "replaced / ours"}}``, medians of interleaved rounds."""
    results = {}
    for row in rows_:
        times = interleaved_ms({"ours": row.calls[0], "replaced": row.calls[1]}, rounds)
        results[row.name] = {
            "ours": row.ours, "replaced": row.replaced, "ours_ms": round(statistics.median(times["ours"]), 3),
            "replaced_ms": round(statistics.median(times["replaced"]), 3),
            "replaced_over_ours": round(median_ratio(times, "replaced", "ours"), 2)}
    return results


@contextlib.contextmanager
def strip_pixels(pixels):
    """Per-pixel stages on the CPU run in strips of ``pixels`` (``None``: whole frames) within the block."""
    chosen = strips.policy_for

    def patched(device):
        return dataclasses.replace(chosen(device), strip_pixels=pixels)

    strips.policy_for = patched
    try:
        yield
    finally:
        strips.policy_for = chosen


def strip_sweep(quick: bool, rounds: int) -> dict:
    """Grade and tone map of the cinematic look at 1920x1080 in strips of each size, over the policy's size."""
    look = tg.PostFX.from_config(Path(__file__).resolve().parents[1] / "export" / "looks" / "cinematic.json")
    stages = torch.nn.Sequential(look.grade, look.tonemap)
    frame = torch.rand(FRAME, generator=torch.Generator().manual_seed(1)) * 4
    threads = torch.get_num_threads()
    taken = policy.STRIP_PIXELS_PER_THREAD * threads
    exponents = (15, 16, 17) if quick else (15, 16, 17, 18, 19)
    sizes = {f"2^{e} a thread": (1 << e) * threads for e in exponents}
    sizes["whole frame"] = None

    def run(pixels):
        def call():
            with strip_pixels(pixels):
                stages(frame)
        return call

    calls = {name: run(pixels) for name, pixels in sizes.items()}
    times = interleaved_ms(calls, rounds)
    baseline = next(name for name, pixels in sizes.items() if pixels == taken)
    return {name: {"ms": round(statistics.median(times[name]), 2), "over_policy": round(median_ratio(times, name, baseline), 2),
                   "policy": name == baseline} for name in sizes}


def lookup_sweep(quick: bool, rounds: int) -> dict:
    """A 33³ tetrahedral LUT with a LogC shaper on a 1920x1080 frame through the operator, its C loop's threads taking
    chunks of each size, over the size it takes (:data:`torchgrade.lut.operator.CHUNK_PIXELS`)."""
    frame = torch.rand(FRAME, generator=torch.Generator().manual_seed(2)) * 8
    lut = tg.LUT3D(identity_table(33), shaper="logc")
    exponents = (14, 15, 16) if quick else (13, 14, 15, 16, 17)
    sizes = {f"2^{e}": 1 << e for e in exponents}
    taken = operator.CHUNK_PIXELS

    def run(pixels):
        def call():
            operator.CHUNK_PIXELS = pixels
            try:
                with torch.no_grad():
                    lut(frame)
            finally:
                operator.CHUNK_PIXELS = taken
        return call

    times = interleaved_ms({name: run(n) for name, n in sizes.items()}, rounds)
    baseline = next(name for name, n in sizes.items() if n == taken)
    return {name: {"ms": round(statistics.median(times[name]), 2), "over_policy": round(median_ratio(times, name, baseline), 2),
                   "policy": name == baseline} for name in sizes}


def _table(title: str, rows_: dict, what: str) -> list:
    lines = [f"## {title}", "", f"| {what} | ms (median) | over the policy's |", "| --- | ---: | ---: |"]
    lines += [f"| {name}{' (the policy)' if r['policy'] else ''} | {r['ms']} | {r['over_policy']} |" for name, r in rows_.items()]
    return lines + [""]


def main(argv=None) -> int:
    args = argument_parser(__doc__, QUICK).parse_args(argv)
    rounds = QUICK_ROUNDS if args.quick else ROUNDS
    forms = compare(rows(), rounds)
    strip_sizes = strip_sweep(args.quick, rounds)
    runs = lookup_sweep(args.quick, rounds)
    threads = torch.get_num_threads()
    lines = ["# The CPU forms against the operations they replace", "",
             f"`{COMMAND}{' --quick' if args.quick else ''}`: medians of {rounds} interleaved rounds on {threads} torch "
             "threads; a ratio is the median over rounds of the two times' ratio (load changes between rounds cancel).", "",
             f"## Forms (bloom's on a {'x'.join(map(str, LEVEL))} level, a strip is {'x'.join(map(str, STRIP))}, a frame "
             f"{'x'.join(map(str, FRAME))}, a fit step 2^16 pixels through a 17³ table)", "",
             "| row | torchgrade's form | replaced form | ours ms | replaced ms | replaced / ours |",
             "| --- | --- | --- | ---: | ---: | ---: |"]
    lines += [f"| {name} | {r['ours']} | {r['replaced']} | {r['ours_ms']} | {r['replaced_ms']} | {r['replaced_over_ours']} |"
              for name, r in forms.items()]
    lines += [""]
    lines += _table(f"Strips: grade and tone map of the cinematic look at 1920x1080 ({threads} threads)", strip_sizes,
                    "strip pixels")
    lines += _table("LUT runs: 33³ tetrahedral, LogC shaper, 1920x1080 (the operator's `CHUNK_PIXELS`)", runs, "chunk pixels")
    report = {"command": COMMAND, "quick": args.quick, "rounds": rounds, "forms": forms, "strips": strip_sizes, "lookup_runs": runs}
    write_results(args.out, "cpu_forms", report, lines[:-1], COMMAND + (" --quick" if args.quick else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
