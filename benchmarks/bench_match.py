"""Learning a look from one before/after pair: accuracy on held-out pixels, fitting time at 1 and 4 megapixels.

The target is made by a tool torchgrade did not write: OpenColorIO 2.6's ``GradingPrimaryTransform`` (linear
style: exposure, contrast, offset, saturation) followed by its built-in ACES 1.0 SDR view, on GoldenGate.exr
(1262x860, 1.1 MP) and on the same picture upscaled 2x bilinearly (4.3 MP). ``tg.match_look`` fits the default
controls, screens the default tone mapper candidates, then fits a 17³ residual LUT; the look is then written
as a 65³ ``.cube`` and read back. Errors are on held-out pixels (8-bit sRGB codes, mean ΔE2000).

A second table is the colourist's check on a look torchgrade made (contrast 25, saturation −15, temperature 18,
hue shift 8, ACES): every default control and tone mapper fitted on the left half of a photograph at a quarter of
its resolution, the errors measured on the right half, which the fit never saw.

Torch runs on ``--threads`` threads (default 1: on a shared 2-core machine one thread was several times faster
than two for these small fits). Writes ``match.json``, ``match.md`` and ``match.png`` (before, target, matched by
the controls, with the residual LUT; the loss curve) to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``).

    .venv/bin/python -m benchmarks match [--threads N] [--out DIR]
"""

from __future__ import annotations

import json
import platform
import tempfile
import time
from pathlib import Path

import torch


import torchgrade as tg
from benchmarks.common import EXR_DIR, argument_parser, ocio_look, write_results

COMMAND = ".venv/bin/python -m benchmarks match"
EXR = EXR_DIR / "GoldenGate.exr"


def fit_once(source: torch.Tensor, target: torch.Tensor) -> tuple:
    """One timed fit (controls, tone mapper screening, residual) and one timed 65³ ``.cube``; the row and the result."""
    start = time.perf_counter()
    result = tg.match_look(source, target, residual=True, progress=False)
    fitted = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        cube = result.write_lut(Path(folder) / "look.cube", size=65)
        baked = time.perf_counter() - start
    row = {"megapixels": source.shape[1] * source.shape[2] / 1e6, "fit_s": fitted, "cube_s": baked,
           "look": result.look.to_config(), "candidates": result.candidates, **result.errors,
           "cube": {**cube, "report": str(cube["report"])}}
    return row, result


def figure(source, target, result, path: Path) -> None:
    """Before (neutral tone mapper), target, matched by the controls, with the residual; below, the loss at every
    evaluation with each phase shaded (screening, Adam, Levenberg-Marquardt, the residual's Adam and L-BFGS)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with torch.no_grad():
        panels = {"before (neutral tone mapper)": tg.ToneMap("neutral")(source[None])[0], "target (OpenColorIO)": target,
                  "matched: controls": result.look.per_pixel_stages()(source[None])[0],
                  "matched: controls + 17³ residual LUT": result(source[None])[0]}
    fig = plt.figure(figsize=(16, 7.5))
    grid = fig.add_gridspec(2, 4, height_ratios=[1.0, 1.0])
    for column, (title, image) in enumerate(panels.items()):
        axis = fig.add_subplot(grid[0, column])
        axis.imshow(tg.color.linear_to_srgb(image.clamp(0, 1)).permute(1, 2, 0).float().numpy())
        axis.set_title(title, fontsize=11)
        axis.axis("off")
    loss = fig.add_subplot(grid[1, :])
    start = 0
    shades = plt.get_cmap("Pastel1").colors
    for index, (phase, count) in enumerate(result.phases):
        loss.axvspan(start - 0.5, start + count - 0.5, color=shades[index % len(shades)], alpha=0.6, lw=0,
                     label=f"{phase} ({count})")
        start += count
    loss.semilogy(result.history, color="black", lw=1.0)
    loss.set_xlim(-0.5, len(result.history) - 0.5)
    loss.set_xlabel("loss evaluation (an Adam step and a Levenberg-Marquardt trial evaluate once, an L-BFGS iteration a few times)", fontsize=10)
    loss.set_ylabel("loss (squared 8-bit codes)", fontsize=10)
    loss.set_title("fitting loss; the residual phases add the LUT's regularisers to a Huber data term", fontsize=11)
    loss.grid(alpha=0.3, which="both", axis="y")
    loss.legend(title="phase (evaluations)", fontsize=9, loc="upper right", ncol=len(result.phases))
    fig.tight_layout()
    fig.savefig(path, dpi=80)


KNOWN_LOOK = {"grade": {"contrast": 25.0, "saturation": -15.0, "temperature": 18.0, "hue_shift": 8.0}, "tonemap": "aces"}
HALVES = ("CandleGlass", "GoldenGate", "Desk")


def known_look_on_halves(name: str) -> dict:
    """:data:`KNOWN_LOOK` fitted with every default on the left half of ``name`` (every 4th pixel), checked on the right."""
    source = tg.io.read_exr(EXR_DIR / f"{name}.exr")[:3, ::4, ::4].double()
    half = source.shape[-1] // 2
    with torch.no_grad():
        target = tg.PostFX(**KNOWN_LOOK)(source[None])[0]
    start = time.perf_counter()
    result = tg.match_look(source[..., :half], target[..., :half], progress=False)
    fitted = time.perf_counter() - start
    with torch.no_grad():
        matched = result.look(source[None, ..., half:])[0]
    errors = tg.match.match_errors(target[..., half:].reshape(3, -1), matched.reshape(3, -1))
    return {"picture": name, "size": list(source.shape[1:]), "fit_s": fitted, "right_half": errors, "look": result.look.to_config()}


def markdown(rows: list, halves: list, threads: int) -> str:
    lines = [f"# Learning a look (bench_match.py, {platform.machine()}, torch {torch.__version__}, {threads} thread(s))", "",
             "Target: OpenColorIO GradingPrimaryTransform + ACES 1.0 SDR view on GoldenGate. Errors on held-out pixels.", "",
             "| MP | fit s | .cube s | controls p99.9 / max / ΔE | + residual p99.9 / max / ΔE | 65³ .cube p99.9 / max / ΔE | tone mapper |",
             "| ---: | ---: | ---: | --- | --- | --- | --- |"]
    for row in rows:
        cells = [f"{row[k]['p99.9']:.2f} / {row[k]['max']:.1f} / {row[k]['delta_e_2000']:.3f}" for k in ("controls", "residual", "cube")]
        lines.append(f"| {row['megapixels']:.1f} | {row['fit_s']:.1f} | {row['cube_s']:.1f} | {' | '.join(cells)} | {row['look']['tonemap']['mode']} |")
    lines += ["", f"Known look ({KNOWN_LOOK}), every default, fitted on the left half; errors on the right half.", "",
              "| picture | pixels | fit s | right half p99.9 / max / ΔE | contrast | tone mapper |", "| --- | --- | ---: | --- | ---: | --- |"]
    for row in halves:
        errors = row["right_half"]
        lines.append(f"| {row['picture']} | {row['size'][1]}×{row['size'][0]} | {row['fit_s']:.1f} | {errors['p99.9']:.2f} / "
                     f"{errors['max']:.2f} / {errors['delta_e_2000']:.4f} | {row['look']['grade']['contrast']:.2f} | {row['look']['tonemap']['mode']} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.threads)
    source = tg.io.read_exr(EXR)[:3].double()
    large = torch.nn.functional.interpolate(source[None], scale_factor=2, mode="bilinear", align_corners=False)[0]
    rows = []
    for picture in (source, large):
        target = ocio_look(picture)
        row, result = fit_once(picture, target)
        rows.append(row)
        print(json.dumps({k: row[k] for k in ("megapixels", "fit_s", "cube_s", "controls", "residual", "cube")}))
        if picture is source:
            figure(source[:, ::2, ::2], target[:, ::2, ::2], result, args.out / "match.png")
    halves = [known_look_on_halves(name) for name in HALVES]
    for row in halves:
        print(json.dumps({k: row[k] for k in ("picture", "fit_s", "right_half")}))
    write_results(args.out, "match", {"threads": args.threads, "rows": rows, "known_look_halves": halves},
                  markdown(rows, halves, args.threads).splitlines(),
                  f"{COMMAND} --threads {args.threads}")


if __name__ == "__main__":
    main()
