"""The suite's methods: every way of computing the look's per-pixel stage (or the whole look), one row each.

Direct evaluation in four dtypes; the default bake (``tg.bake_lut`` with every default) looked up both ways a CPU
runs it (:mod:`benchmarks.suite.forms`); a 33³ LogC LUT (the twin of OpenColorIO's row); ``look.to_lut()``'s
baked look; in the full run every LUT size × lattice × interpolation and lattices fitted to the scenes;
``torch.compile``; and the exported runtimes (:mod:`benchmarks.suite.runtimes`). Part of
``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

import functools
import time
from typing import Callable, Optional

import torch

import torchgrade as tg
from benchmarks.suite import runtimes
from benchmarks.suite.forms import FORMS, TORCH_FORM, compiled_loop_runs, lookup_form
from benchmarks.suite.rows import Method, default_name, lut_info, lut_name
from benchmarks.suite.workload import GRID_SIZES, Workload, float32_lut, grid_shapers

__all__ = ["INTERPOLATIONS", "HDR_UNUSABLE", "PEER", "WHOLE_LOOK", "PER_PIXEL", "BAKED_LOOK", "method_rows"]

HDR_UNUSABLE = "linear"
"""The shaper whose lattice clips everything above 1: its rows are kept in the table, never offered for HDR."""
INTERPOLATIONS = ("tetrahedral", "trilinear")
FITTED_SIZES = (33, 65)
"""Sizes also baked with the lattice reaching the scenes' brightest pixel (tetrahedral rows, full run)."""
PEER = runtimes.PEER
WHOLE_LOOK, PER_PIXEL = "direct float32, whole look", "direct float32"


def direct_rows(work: Workload) -> list:
    """The per-pixel stage evaluated in each dtype (float64, the reference itself, in the full run), and the whole look."""
    dtypes = {"float64 (reference)": torch.float64} if work.plan.every_row else {}
    dtypes.update({"float32": torch.float32, "bfloat16": torch.bfloat16, "float16": torch.float16})
    rows = [(f"direct {label}", functools.partial(Method, f"direct {label}", "direct", work.per_pixel, dtype))
            for label, dtype in dtypes.items()]
    rows.append((WHOLE_LOOK, functools.partial(Method, WHOLE_LOOK, "direct", work.look, whole_look=True)))
    return rows


def looked_up(lut: tg.LUT3D, interpolation: str, form: Optional[str] = None) -> Callable:
    """``lut(x, interpolation)``, in CPU lookup ``form`` (:func:`~benchmarks.suite.forms.lookup_form`) when given."""
    if form is None:
        return lambda x: lut(x, interpolation)

    def apply(x):
        with lookup_form(form):
            return lut(x, interpolation)

    return apply


def default_rows(work: Workload) -> list:
    """The default bake, each interpolation in each CPU form (trilinear's torch form in the full run; on a GPU, once:
    the forms are CPU forms)."""

    def build(interpolation, form):
        lut = work.default_lut
        info = lut_info(lut, interpolation, default_bake=True)
        if form is not None:
            looped = form == TORCH_FORM or compiled_loop_runs(interpolation)
            info["lookup_form"] = form if looped else f"{TORCH_FORM}: the loop did not compile here"
        return Method(default_name(lut, interpolation, form), "lut", looked_up(lut, interpolation, form), info=info)

    lut = work.default_lut
    keys = [(i, f) for i in INTERPOLATIONS for f in FORMS if work.plan.every_row or (i, f) != ("trilinear", TORCH_FORM)]
    if work.plan.device.type != "cpu":
        keys = [(i, None) for i in INTERPOLATIONS]
    return [(default_name(lut, i, f), functools.partial(build, i, f)) for i, f in keys]


def grid_keys(work: Workload) -> list:
    """``(size, shaper, interpolation, headline)`` of the LUT rows: 33³ LogC tetrahedral (OpenColorIO's twin) in every
    run, and in the full run every size × lattice × interpolation."""
    keys = {(33, "logc", "tetrahedral"): True}
    if work.plan.every_row:
        for key in ((s, shaper, i) for s in GRID_SIZES for shaper in grid_shapers() for i in INTERPOLATIONS):
            keys.setdefault(key, False)
    return [(*key, headline) for key, headline in keys.items()]


def fitted_lut_name(size: int) -> str:
    return f"LUT {size}³ logc tetrahedral, domain fitted to the scenes"


def lut_rows(work: Workload) -> list:
    def build(size, shaper, interpolation, headline):
        lut = work.lut(size, shaper)
        info = lut_info(lut, interpolation)
        return Method(lut_name(size, shaper, interpolation), "lut", looked_up(lut, interpolation), info=info, headline=headline)

    def build_fitted(size):
        lut = work.lut(size, "logc", fitted=True)
        top = float(tg.color.logc_to_linear(lut.domain_max.double()).max())
        info = lut_info(lut, "tetrahedral", domain_top_linear=round(top, 1))
        return Method(fitted_lut_name(size), "lut", looked_up(lut, "tetrahedral"), info=info, headline=False)

    rows = [(lut_name(*key[:3]), functools.partial(build, *key)) for key in grid_keys(work)]
    if work.plan.every_row:
        rows += [(fitted_lut_name(size), functools.partial(build_fitted, size)) for size in FITTED_SIZES]
    return rows


BAKED_LOOK = "baked look (look.to_lut()), whole look"


def baked_look_rows(work: Workload) -> list:
    """``look.to_lut()``: eye adaptation and bloom live, the per-pixel stage through the default bake."""
    def build():
        look = work.baked_look
        return Method(BAKED_LOOK, "lut", look, whole_look=True,
                      info=lut_info(look.lut, look.lut.interpolation, default_bake=True))

    return [(BAKED_LOOK, build)]


def compile_rows(work: Workload) -> list:
    """``torch.compile`` through the library's door, ``tg.compile``, of the direct float32 stage and of the whole look,
    and of the default bake's lookups (``LUT3D(compile=True)``); compile time = the first call at 1080p (the accuracy
    scenes' other sizes then compile once more, with symbolic sizes)."""

    def build(name, module, whole_look=False, interpolation=None):
        apply = (lambda x: module(x, interpolation)) if interpolation else module
        frame = work.frame if whole_look else work.per_pixel_frame(torch.float32)
        start = time.perf_counter()
        with torch.no_grad():
            apply(frame)
        if isinstance(module, tg.LUT3D) and not module.compile:
            raise RuntimeError("torch.compile failed; LUT3D fell back to its eager lookup")
        info = {"compile_s": round(time.perf_counter() - start, 1)}
        if interpolation:
            info.update(lut_info(module, interpolation), default_bake=True)
        return Method(name, "torch.compile", apply, whole_look=whole_look, info=info)

    rows = [("torch.compile direct float32", lambda: build("torch.compile direct float32", tg.compile(work.per_pixel))),
            ("torch.compile whole look", lambda: build("torch.compile whole look", tg.compile(work.look), whole_look=True))]
    for interpolation in INTERPOLATIONS:
        name = f"torch.compile {default_name(work.default_lut, interpolation)}"
        rows.append((name, functools.partial(
            lambda n, i: build(n, float32_lut(work.default_lut, compile=True), interpolation=i), name, interpolation)))
    return rows


def method_rows(work: Workload) -> list:
    """Every row as ``(name, build)``; rows of a CPU runtime are left out on other devices."""
    rows = direct_rows(work) + default_rows(work) + lut_rows(work) + baked_look_rows(work)
    if work.plan.compile:
        rows += compile_rows(work)
    if work.plan.device.type == "cpu":
        rows += runtimes.runtime_rows(work)
    return rows
