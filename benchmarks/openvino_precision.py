"""OpenVINO at its default inference precision (bfloat16 on CPUs that have it) against PyTorch: the error of
exported looks in 8-bit sRGB codes on the demo scene, the figure ``tests/onnx/test_openvino.py`` bounds.

    .venv/bin/python -m benchmarks openvino_precision

Each look (parts of ``export/looks/cinematic.json``, tone mapped with ACES, and the whole look) is exported with
:func:`torchgrade.onnx.export` and run on OpenVINO's CPU plugin with no precision hint; its display-linear output
and PyTorch's are clipped to [0, 1], sRGB-encoded and compared in codes at 333x517, the test's largest frame.
A second table exports the grade + ACES look with the grade's colour matrices
(:func:`torchgrade.base.planes.apply_matrix`; the ACES fit's own stay as they are) as torchgrade exports them (three
products of planes) and as the two one-node forms it does not take, a ``MatMul`` and an ``Einsum``.
Writes openvino_precision.json and openvino_precision.md to ``--out`` (default benchmarks/out; the committed ones
with ``--out benchmarks/results``).
"""

from __future__ import annotations

import contextlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

import torchgrade as tg
from benchmarks.common import argument_parser, write_results
from torchgrade.base import planes

ROOT = Path(__file__).resolve().parents[1]

LOOK = ROOT / "export" / "looks" / "cinematic.json"
COMMAND = ".venv/bin/python -m benchmarks openvino_precision"
HEIGHT, WIDTH = 333, 517


def looks() -> dict:
    """The looks compared: each stage before ACES, and the whole cinematic look."""
    config = json.loads(LOOK.read_text())
    parts = {f"{stage} + ACES": {stage: config[stage], "tonemap": "aces"} for stage in ("exposure", "bloom", "grade")}
    return {**parts, "cinematic look": config}


def codes(linear: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes (unrounded) of display-linear values clipped to [0, 1]."""
    return tg.color.transfer.linear_to_srgb(torch.as_tensor(linear).clamp(0.0, 1.0)).numpy() * 255.0


def code_error(config: dict, folder: Path) -> dict:
    """``{"max": codes, "p999": codes}`` of one look at OpenVINO's default precision."""
    look = tg.PostFX.from_config(config).eval()
    runner = tg.onnx.session(tg.onnx.export(look, folder / "look.onnx"), "openvino")
    inputs = tg.onnx.graph_inputs(look, tg.scene.demo_scene(HEIGHT, WIDTH))
    error = np.abs(codes(runner.run(None, tg.onnx.feeds(runner, look, inputs))[0]) - codes(tg.onnx.reference(look, inputs)[0].numpy()))
    return {"max": round(float(error.max()), 2), "p999": round(float(np.percentile(error, 99.9)), 2)}


def _matmul(matrix: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    return (image.movedim(-3, -1) @ matrix.mT).movedim(-1, -3)


def _einsum(matrix: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    return torch.einsum("ij,...jhw->...ihw" if matrix.dim() == 2 else "bij,bjhw->bihw", matrix, image)


MATRIX_FORMS = {"three products of planes (torchgrade's)": None, "MatMul": _matmul, "Einsum": _einsum}
"""The exported forms of a colour matrix compared: ``None`` is torchgrade's own."""


@contextlib.contextmanager
def matrices_exported_as(form):
    """The grade's colour matrices (:func:`~torchgrade.base.planes.matrix_on`) computed, and so exported, as
    ``form(matrix, image)`` within the block (``None``: torchgrade's own form)."""
    kept = planes.apply_matrix
    planes.apply_matrix = kept if form is None else form
    try:
        yield
    finally:
        planes.apply_matrix = kept


def main(argv=None) -> int:
    args = argument_parser(__doc__).parse_args(argv)
    import openvino

    with tempfile.TemporaryDirectory() as folder:
        rows = {name: code_error(config, Path(folder)) for name, config in looks().items()}
        matrices = {}
        for name, form in MATRIX_FORMS.items():
            with matrices_exported_as(form):
                matrices[name] = code_error(looks()["grade + ACES"], Path(folder))
    report = {"command": COMMAND, "openvino": openvino.__version__, "frame": [HEIGHT, WIDTH], "results": rows,
              "colour_matrices": matrices}
    lines = [f"# OpenVINO default precision vs PyTorch: demo scene {WIDTH}x{HEIGHT}, 8-bit sRGB codes", "",
             f"`{COMMAND}` (OpenVINO {openvino.__version__}, CPU plugin, no precision hint)", "",
             "| look | max | p99.9 |", "| --- | ---: | ---: |"]
    lines += [f"| {name} | {r['max']} | {r['p999']} |" for name, r in rows.items()]
    lines += ["", "## Colour matrices: grade + ACES with the grade's matrices exported as", "", "| form | max | p99.9 |",
              "| --- | ---: | ---: |"]
    lines += [f"| {name} | {r['max']} | {r['p999']} |" for name, r in matrices.items()]
    write_results(args.out, "openvino_precision", report, lines, COMMAND)
    return 0


if __name__ == "__main__":
    sys.exit(main())
