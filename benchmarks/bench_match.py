"""Learning a look: whether ``tg.match_look`` finds the tone mapper, how well its held-out figure predicts the rest of
the picture, and what a fit of a photograph costs.

1. **A known look with every SDR tone mapper** (:data:`LOOK`: contrast −10, saturation 30, temperature −20, tint 10,
   then each mode of ``TONEMAP_CANDIDATES``), fitted with every default on the left half of a photograph; the truth
   is the fitted look against the known one on every pixel of the right half, which the fit never saw. Columns:
   the tone mapper found, the truth and the held-out figure (p99.9 / max, 8-bit sRGB codes), their ratio, whether
   the row meets the bar (:func:`recovered`), the contrast and exposure found (the recipe: −10 and 0).
2. **Out of reach**: the same look fitted with a tone mapper that is not its own (``tonemaps=`` one mode), so the
   errors are codes, not rounding; the held-out figure against the truth, and against every pixel of the left half
   (the fitted ones too), the picture its blocks are drawn from.
3. **A photograph**: a look made by OpenColorIO (``GradingPrimaryTransform`` then its ACES 1.0 SDR view) learnt
   from GoldenGate (1262x860, 1.1 MP; the full run also at 2x, 4.3 MP) with every default and a 17³ residual LUT,
   then written as a 65³ ``.cube`` and read back; errors on the held-out blocks; the fit's wall and CPU seconds.
4. **The Jacobian** (full run): one batch of forward differences against ``torch.func.jacfwd``, for every default
   control of a candidate on the default 16,384 fitting pixels (ms, median of 5).

Torch runs on ``--threads`` threads (default 1: a fit works on batches of a few hundred thousand values, and on a
shared 2-core machine a second thread mostly waits for the first; ``--threads 2`` to compare). ``--quick`` measures
accuracy only (no timings) on GoldenGate at every 8th pixel for parts 1 and 2, and part 3 at 1.1 MP; it writes
``match_quick.{md,json,png}``, the full run ``match.{md,json,png}`` (every 4th pixel of GoldenGate, CandleGlass and
Desk), to ``--out`` (default benchmarks/out; the committed ones with ``--out benchmarks/results``), each stamped with
the commit it measured; the tables are marked so that ``python -m benchmarks suite --pages`` copies them onto
docs/match.md (:func:`marked`). The figure:
before, target, matched by the controls, with the residual LUT; the loss at every evaluation by phase.

    .venv/bin/python -m benchmarks match [--quick] [--threads N] [--out DIR]
"""

from __future__ import annotations

import json
import statistics
import tempfile
import time
from pathlib import Path

import torch

import torchgrade as tg
from benchmarks.common import EXR_DIR, argument_parser, mark_table, ocio_look, write_results
from benchmarks.suite.stamp import source_commit
from torchgrade.match import TONEMAP_CANDIDATES, MatchedControls, match_errors

COMMAND = ".venv/bin/python -m benchmarks match"
QUICK = "accuracy only (no timings), GoldenGate at every 8th pixel for the tone mappers, 1.1 MP only"

LOOK = {"contrast": -10.0, "saturation": 30.0, "temperature": -20.0, "tint": 10.0}
OUT_OF_REACH = (("agx", "neutral"), ("hable", "aces"), ("aces", "reinhard"), ("aces2", "agx"), ("khronos_pbr_neutral", "hable"))
"""(the look's tone mapper, the one fitted) pairs of part 2."""


def timed(call) -> tuple:
    """``(call's value, wall seconds, CPU seconds of this process)``."""
    wall, cpu = time.perf_counter(), time.process_time()
    value = call()
    return value, time.perf_counter() - wall, time.process_time() - cpu


def rounded(errors: dict) -> dict:
    return {name: round(value, 4) for name, value in errors.items()}


def halves(name: str, step: int) -> tuple:
    source = tg.io.read_exr(EXR_DIR / f"{name}.exr")[:3, ::step, ::step].double()
    return source, source.shape[-1] // 2


def fitted_half(source, half: int, target, **options) -> dict:
    """``match_look`` with every default (but ``options``) on the left half; the truth on every pixel of the right, and
    on every pixel of the left (the fitted ones too), the picture the held-out blocks stand for."""
    result, wall, cpu = timed(lambda: tg.match_look(source[..., :half], target[..., :half], progress=False, **options))
    with torch.no_grad():
        matched = result.look(source[None])[0]
    truth, left = (match_errors(target[..., side].reshape(3, -1), matched[..., side].reshape(3, -1))
                   for side in (slice(half, None), slice(None, half)))
    config = result.look.to_config()
    return {"found": config["tonemap"]["mode"], "truth": rounded(truth), "held_out": rounded(result.errors["controls"]),
            "left_half": rounded(left),
            "contrast": config["grade"].get("contrast", 0.0), "post_exposure": config["grade"].get("post_exposure", 0.0),
            "finalists": list(result.finalists), "fit_s": wall, "fit_cpu_s": cpu}


def known_looks(pictures: list, step: int) -> list:
    rows = []
    for picture in pictures:
        source, half = halves(picture, step)
        for mode in TONEMAP_CANDIDATES:
            with torch.no_grad():
                target = tg.PostFX(grade=LOOK, tonemap=mode)(source[None])[0]
            rows.append({"picture": picture, "size": list(source.shape[1:]), "mode": mode, **fitted_half(source, half, target)})
            print(json.dumps({key: rows[-1][key] for key in ("picture", "mode", "found", "truth", "held_out", "fit_cpu_s")}))
    return rows


def out_of_reach(pictures: list, step: int) -> list:
    rows = []
    for picture in pictures:
        source, half = halves(picture, step)
        for mode, fitted in OUT_OF_REACH:
            with torch.no_grad():
                target = tg.PostFX(grade=LOOK, tonemap=mode)(source[None])[0]
            rows.append({"picture": picture, "mode": mode, **fitted_half(source, half, target, tonemaps=fitted)})
            print(json.dumps({key: rows[-1][key] for key in ("picture", "mode", "found", "truth", "held_out")}))
    return rows


def photograph(source: torch.Tensor) -> tuple:
    """One timed fit of OpenColorIO's look (controls, screening, residual) and one timed 65³ ``.cube``; the row and the result."""
    target = ocio_look(source)
    result, wall, cpu = timed(lambda: tg.match_look(source, target, residual=True, progress=False))
    with tempfile.TemporaryDirectory() as folder:
        cube, cube_s, _ = timed(lambda: result.write_lut(Path(folder) / "look.cube", size=65))
    row = {"megapixels": source.shape[1] * source.shape[2] / 1e6, "fit_s": wall, "fit_cpu_s": cpu, "cube_s": cube_s,
           "look": result.look.to_config(), "candidates": result.candidates, "finalists": result.finalists,
           **{name: rounded(errors) for name, errors in result.errors.items()},
           "cube": {**rounded({k: v for k, v in cube.items() if k != "report"}), "report": str(cube["report"])}}
    return row, result, target


def jacobians() -> dict:
    """ms of one Jacobian of every default control (with ``aces``) on 16,384 pixels: batched forward differences
    (float32, as the fit computes them) against ``torch.func.jacfwd`` (float64)."""
    from torchgrade.match.solver import forward_differences

    model = MatchedControls(tg.match.GRADE_CONTROLS, "aces").double()
    pixels = halves("GoldenGate", 4)[0].reshape(1, 3, -1, 1)[:, :, :16384]
    names = [name for name, _ in model.named_parameters()]
    sizes = [p.numel() for _, p in model.named_parameters()]
    theta = torch.cat([p.detach().flatten() for _, p in model.named_parameters()])

    def values(batch, dtype):
        return {name: piece.to(dtype).reshape(len(batch), *p.shape)
                for name, piece, p in zip(names, batch.split(sizes, dim=1), model.parameters())}

    def residuals(batch, dtype):
        shown = torch.func.functional_call(model, values(batch, dtype), (pixels.to(dtype).expand(len(batch), -1, -1, -1),))
        return shown.reshape(len(batch), -1)

    def forward_mode():
        return torch.func.jacfwd(lambda t: residuals(t[None], torch.float64)[0])(theta)

    times = {}
    for name, call in (("forward differences, one batch (float32)", lambda: forward_differences(residuals, theta, torch.float32)),
                       ("torch.func.jacfwd (float64)", forward_mode)):
        with torch.no_grad() if "differences" in name else torch.enable_grad():
            call()
            times[name] = statistics.median(timed(call)[1] * 1e3 for _ in range(5))
    return {"parameters": len(theta), "pixels": 16384, "ms": times}


def figure(source, target, result, path: Path) -> None:
    """Before (neutral tone mapper), target, matched by the controls, with the residual; below, the loss at every
    evaluation with each phase shaded (global controls, every control, the residual's Adam and L-BFGS)."""
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
    loss.set_xlabel("loss evaluation (a Levenberg-Marquardt trial evaluates once, an L-BFGS iteration a few times)", fontsize=10)
    loss.set_ylabel("loss (squared 8-bit codes)", fontsize=10)
    loss.set_title("fitting loss of the chosen tone mapper; the residual phases add the LUT's regularisers to a Huber data term", fontsize=11)
    loss.grid(alpha=0.3, which="both", axis="y")
    loss.legend(title="phase (evaluations)", fontsize=9, loc="upper right", ncol=len(result.phases))
    fig.tight_layout()
    fig.savefig(path, dpi=80)


def _pair(errors: dict) -> str:
    return f"{errors['p99.9']:.2f} / {errors['max']:.2f}"


def _ratio(row: dict) -> str:
    truth, held = row["truth"]["p99.9"], row["held_out"]["p99.9"]
    return "both < 0.01" if max(truth, held) < 0.01 else f"{held / truth:.2f}"


RECOVERED, FORESEEN = 0.5, 1.5
"""The bar a known look meets: p99.9 at most half a code on the right half and on the held-out blocks, and the
held-out figure within 1.5x of the right half's either way (or both under a hundredth of a code)."""


def foreseen(row: dict) -> bool:
    """Whether the held-out p99.9 is within :data:`FORESEEN` times the right half's either way (both under 0.01: yes)."""
    truth, held = row["truth"]["p99.9"], row["held_out"]["p99.9"]
    return max(truth, held) < 0.01 or (truth > 0 and 1 / FORESEEN <= held / truth <= FORESEEN)


def recovered(row: dict) -> bool:
    return max(row["truth"]["p99.9"], row["held_out"]["p99.9"]) <= RECOVERED and foreseen(row)


def verdict(rows: list) -> str:
    """How many known looks meet the bar (:func:`recovered`), naming those that do not."""
    missed = [f"{row['mode']} on {row['picture']}" for row in rows if not recovered(row)]
    return (f"{len(rows) - len(missed)} of {len(rows)} meet the bar (p99.9 ≤ {RECOVERED} codes on the right half and on "
            f"the held-out blocks, the held-out figure within {FORESEEN}× of the right half's){'; not: ' + ', '.join(missed) if missed else ''}.")


def marked(name: str, table: list) -> list:
    """``table``'s lines between ``<!-- match:NAME -->`` and ``<!-- /match:NAME -->``, the marks by which
    ``python -m benchmarks suite --pages`` copies it onto docs/match.md (:data:`benchmarks.suite.pages.MATCH_TABLES`)."""
    return mark_table("match", name, table)


def known_table(rows: list, timing: bool) -> list:
    lines = ["| picture | tone mapper | found | truth | held-out | held-out / truth | bar | contrast | exposure |"
             + (" fit s | CPU s |" if timing else ""),
             "| --- | --- | --- | --- | --- | ---: | --- | ---: | ---: |" + (" ---: | ---: |" if timing else "")]
    for row in rows:
        cells = [row["picture"], row["mode"], row["found"], _pair(row["truth"]), _pair(row["held_out"]), _ratio(row),
                 "met" if recovered(row) else "**missed**", f"{row['contrast']:.3f}", f"{row['post_exposure']:.4f}"]
        cells += [f"{row['fit_s']:.1f}", f"{row['fit_cpu_s']:.1f}"] if timing else []
        lines.append("| " + " | ".join(cells) + " |")
    return lines + ["", verdict(rows)]


def reach_table(rows: list) -> list:
    higher = sum(row["held_out"]["p99.9"] > row["truth"]["p99.9"] for row in rows)
    lower = sum(row["held_out"]["p99.9"] < row["truth"]["p99.9"] for row in rows)
    return ["| picture | look's tone mapper | fitted | truth | held-out | held-out / truth | left half, every pixel |",
            "| --- | --- | --- | --- | --- | ---: | --- |"] + [
        f"| {row['picture']} | {row['mode']} | {row['found']} | {_pair(row['truth'])} | {_pair(row['held_out'])} | {_ratio(row)} "
        f"| {_pair(row['left_half'])} |" for row in rows] + ["", f"The held-out p99.9 is within {FORESEEN}× of the right half's for {sum(map(foreseen, rows))} of "
                                f"{len(rows)} looks; it is the higher of the two for {higher} and the lower for {lower}."]


def photograph_table(rows: list, timing: bool) -> list:
    lines = ["| MP | controls | + residual | 65³ .cube | tone mapper |" + (" fit s | CPU s | .cube s |" if timing else ""),
             "| ---: | --- | --- | --- | --- |" + (" ---: | ---: | ---: |" if timing else "")]
    for row in rows:
        cells = [f"{row[k]['p99.9']:.2f} / {row[k]['max']:.2f} / {row[k]['delta_e_2000']:.4f}" for k in ("controls", "residual", "cube")]
        extra = f" {row['fit_s']:.1f} | {row['fit_cpu_s']:.1f} | {row['cube_s']:.1f} |" if timing else ""
        lines.append(f"| {row['megapixels']:.1f} | {' | '.join(cells)} | {row['look']['tonemap']['mode']} |{extra}")
    return lines


def markdown(report: dict, quick: bool) -> list:
    """The results page: each part's table marked (:func:`marked`) as ``known``, ``reach``, ``photograph`` and, in
    the full run, ``jacobian``."""
    timing = not quick
    stamp = f"`{report['commit'][:7]}`{' with uncommitted changes' if report['modified'] else ''}"
    lines = [f"# Learning a look (bench_match.py{' --quick' if quick else ''}, {report['threads']} thread(s))", "",
             f"Made by `{report['command']}` at commit {stamp}.", "",
             f"## 1. A known look with every SDR tone mapper ({LOOK}), every default", "",
             "Fitted on the left half of each picture; *truth*: the fitted look against the known one on every pixel of the "
             "right half; *held-out*: `result.errors['controls']`, every pixel of the left half's held-out blocks. "
             "p99.9 / max in 8-bit sRGB codes.", "", *marked("known", known_table(report["known_looks"], timing)),
             "", "## 2. Out of reach: the look fitted with another tone mapper", "", *marked("reach", reach_table(report["out_of_reach"])),
             "", "## 3. A photograph: OpenColorIO's look on GoldenGate, every default, a 17³ residual LUT", "",
             "Errors on the held-out blocks (p99.9 / max / mean ΔE2000).", "",
             *marked("photograph", photograph_table(report["photographs"], timing))]
    if "jacobian" in report:
        jacobian = report["jacobian"]
        lines += ["", f"## 4. One Jacobian: {jacobian['parameters']} parameters, {jacobian['pixels']} pixels", "",
                  *marked("jacobian", ["| form | ms |", "| --- | ---: |"] + [f"| {name} | {ms:.0f} |" for name, ms in jacobian["ms"].items()])]
    return lines


def main(argv=None) -> None:
    parser = argument_parser(__doc__, QUICK)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.threads)
    stem = "match_quick" if args.quick else "match"
    pictures, step = (["GoldenGate"], 8) if args.quick else (["GoldenGate", "CandleGlass", "Desk"], 4)
    command = f"{COMMAND}{' --quick' if args.quick else ''} --threads {args.threads} --out {args.out}"
    report = {"command": command, **source_commit(), "threads": args.threads, "look": LOOK,
              "known_looks": known_looks(pictures, step),
              "out_of_reach": out_of_reach(pictures, step), "photographs": []}
    source = tg.io.read_exr(EXR_DIR / "GoldenGate.exr")[:3].double()
    scales = (source,) if args.quick else (source, torch.nn.functional.interpolate(source[None], scale_factor=2, mode="bilinear", align_corners=False)[0])
    for index, picture in enumerate(scales):
        row, result, target = photograph(picture)
        report["photographs"].append(row)
        print(json.dumps({k: row[k] for k in ("megapixels", "fit_s", "fit_cpu_s", "controls", "residual", "cube")}))
        if index == 0:
            figure(source[:, ::2, ::2], target[:, ::2, ::2], result, args.out / f"{stem}.png")
    if not args.quick:
        report["jacobian"] = jacobians()
    else:  # accuracy only: a busy machine's seconds are not kept
        for row in report["known_looks"] + report["out_of_reach"] + report["photographs"]:
            for key in ("fit_s", "fit_cpu_s", "cube_s"):
                row.pop(key, None)
    write_results(args.out, stem, report, markdown(report, args.quick), command)


if __name__ == "__main__":
    main()
