"""The suite's rows of other runtimes: the look exported to ONNX and run by onnxruntime and OpenVINO, and LUTs
applied by OpenColorIO's CPU processor (a ``.cube`` file, and the default bake as CLF, whose shaper is exact).

Part of ``.venv/bin/python -m benchmarks suite [--quick] [--out DIR]``.
"""

from __future__ import annotations

import functools
import os
import time
from pathlib import Path

import torch
from torch import nn

import torchgrade as tg
from benchmarks.common import ocio_apply, ocio_in_place, ocio_processor
from benchmarks.suite.rows import Method, default_name, lut_info, lut_name
from benchmarks.suite.workload import GRID_SIZES, LOOK, Workload

__all__ = ["PEER", "OPENVINO_PRECISION", "runtime_rows"]

PEER = "OpenColorIO 33³ logc tetrahedral"
"""The row every per-pixel row's time is also divided by (the peer a colourist would use)."""
OPENVINO_PRECISION = "f32"
"""OpenVINO's inference precision hint in every run: its default follows the CPU (bfloat16 where the CPU has it), so
the accuracy of a default-precision row is the machine's; the full run adds that row for the whole look."""
CUBE_SHAPERS = ("linear", "logc", "logc_hdr")
"""Lattices a ``.cube`` file holds exactly (its 1D section samples linear values evenly: a longer tail is clamped)."""


def models(work: Workload) -> dict:
    """What is exported, by name: ``(module, whole look?, record fields)``: the whole look, the default bake (a look of
    that LUT alone) and, in the full run, the baked look (``look.to_lut()``) and the per-pixel stage."""
    lut = work.default_lut.cpu()
    found = {"whole look": (tg.PostFX.from_config(LOOK), True, {})}
    for interpolation in ("tetrahedral", "trilinear") if work.plan.every_row else ("tetrahedral",):
        found[default_name(lut, interpolation)] = (tg.PostFX(lut=lut, interpolation=interpolation), False,
                                                   lut_info(lut, interpolation, default_bake=True))
    if work.plan.every_row:  # a second whole look to export, and a per-pixel stage the whole look stands for
        found["baked look, whole look"] = (work.baked_look.cpu(), True, lut_info(lut, lut.interpolation, default_bake=True))
        found["direct float32"] = (tg.PostFX(grade=LOOK["grade"], tonemap=LOOK["tonemap"]), False, {})
    return found


def exported(work: Workload, stem: str, module: nn.Module) -> tuple:
    """``(path, export seconds, nodes)`` of ``module`` exported by :func:`torchgrade.onnx.export`, once per run."""
    if stem not in work.exports:
        path = work.folder / f"{len(work.exports)}.onnx"
        start = time.perf_counter()
        tg.onnx.export(module, path)
        work.exports[stem] = (path, round(time.perf_counter() - start, 1), tg.onnx.node_count(path))
    return work.exports[stem]


def onnxruntime_session(path: Path):
    """onnxruntime CPU session, one intra-op thread per core, arena off (so peak memory is per run)."""
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = os.cpu_count()
    options.enable_cpu_mem_arena = False
    return onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


SESSIONS = {"onnxruntime": onnxruntime_session,
            "OpenVINO": functools.partial(tg.onnx.session, runtime="openvino", precision=OPENVINO_PRECISION)}
"""How each runtime opens a file."""


def exported_method(work: Workload, runtime: str, stem: str, opener=None) -> Method:
    """The model ``stem`` of :func:`models` exported and run by ``runtime``, fed by :func:`torchgrade.onnx.feeds`."""
    module, whole_look, info = models(work)[stem]
    path, export_s, nodes = exported(work, stem, module)
    session = (opener or SESSIONS[runtime])(path)

    def apply(image):
        return torch.from_numpy(session.run(None, tg.onnx.feeds(session, module, image.detach().cpu().float()))[0])

    def timer(frame):
        feeds = tg.onnx.feeds(session, module, frame.detach().cpu().float())
        return (lambda: session.run(None, feeds)), None

    name = f"{runtime} {stem}"
    return Method(name, runtime.lower(), apply, whole_look=whole_look, host=True, timer=timer,
                  info={**info, "export_s": export_s, "onnx_nodes": nodes})


def exported_rows(work: Workload) -> list:
    rows = [(f"{runtime} {stem}", functools.partial(exported_method, work, runtime, stem))
            for runtime in SESSIONS for stem in models(work)]
    if work.plan.every_row:
        name = "OpenVINO default precision whole look"
        default = functools.partial(tg.onnx.session, runtime="openvino")
        rows.append((name, lambda: _renamed(exported_method(work, "OpenVINO", "whole look", default), name)))
    return rows


def _renamed(method: Method, name: str) -> Method:
    method.name = name
    return method


def opencolorio_method(work: Workload, lut: tg.LUT3D, name: str, suffix: str, interpolation: str, headline: bool) -> Method:
    """``lut`` written as a ``.cube`` (``suffix`` ``".cube"``, :func:`torchgrade.io.write_cube`) or CLF (``".clf"``,
    :func:`torchgrade.io.write_clf`) and applied by OpenColorIO's CPU processor."""
    path = work.folder / f"{len(list(work.folder.iterdir()))}{suffix}"  # a fresh path per table: OpenColorIO caches by path
    if suffix == ".cube":
        tg.io.write_cube(path, lut.cpu())
    else:  # a CLF file names its interpolation, which OpenColorIO follows
        tg.io.write_clf(path, lut.cpu(), interpolation=interpolation)
    processor = ocio_processor(path, interpolation)
    return Method(name, "opencolorio", functools.partial(ocio_apply, processor), host=True,
                  timer=functools.partial(ocio_in_place, processor), info=lut_info(lut, interpolation), headline=headline)


def opencolorio_rows(work: Workload) -> list:
    """OpenColorIO on the 33³ LogC ``.cube`` (:data:`PEER`) and the default bake as CLF in every run; the full run adds
    every grid size × ``.cube`` lattice × interpolation."""
    keys = {(33, "logc", "tetrahedral"): True}
    if work.plan.every_row:
        for key in ((s, shaper, i) for s in GRID_SIZES for shaper in CUBE_SHAPERS for i in ("tetrahedral", "trilinear")):
            keys.setdefault(key, False)
    rows = []
    for (size, shaper, interpolation), headline in keys.items():
        name = f"OpenColorIO {lut_name(size, shaper, interpolation).removeprefix('LUT ')}"
        rows.append((name, functools.partial(lambda *key: opencolorio_method(work, work.lut(*key[:2]), *key[2:]),
                                             size, shaper, name, ".cube", interpolation, headline)))
    for interpolation in ("tetrahedral", "trilinear") if work.plan.every_row else ("tetrahedral",):
        name = f"OpenColorIO {default_name(work.default_lut, interpolation).removeprefix('LUT ')} (CLF)"
        rows.append((name, functools.partial(lambda n, i: opencolorio_method(work, work.default_lut, n, ".clf", i, True),
                                             name, interpolation)))
    return rows


def runtime_rows(work: Workload) -> list:
    return exported_rows(work) + opencolorio_rows(work)
