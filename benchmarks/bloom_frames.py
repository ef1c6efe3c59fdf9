"""Bloom on whole frames: uniform fields, turned frames, edge bands on photographs, light, and Unity's passes.

Not a timing: what a per-pixel reference does not see, measured at the sizes users render (odd, prime, 720p, 1080p).

* **Uniform fields**: ``(max - min) / mean`` of each mode's output on a field of 8.0 at each size.
* **Turned frames**: the largest difference between the bloom of a frame turned by 180° (turned back) and the bloom of
  the frame, relative to the largest glow, on HDR noise with bright points.
* **Edge bands**: the shipped look (``export/looks/cinematic.json``, as a still) on every sample photograph at full
  size: how much brighter each 16-pixel edge band is, in 8-bit codes, than the photograph rendered turned by 180°
  and turned back (:func:`torchgrade.testing.frames.edge_band_codes`).
* **Light**: scattering's ``sum(out) / sum(in) - 1`` at odd sizes (float64).
* **Unity's passes** (``tests/reference/bloom.py``, the shader passes transcribed in float64): how far torchgrade's
  glow lies from them on the Desk photograph, with Unity's clamped edge and with the mirrored edge torchgrade takes.

Run from the repository root::

    .venv/bin/python -m benchmarks bloom_frames [--out DIR]
"""

from __future__ import annotations


import numpy as np
import torch
import torch.nn.functional as F


import torchgrade as tg
from benchmarks.common import EXR_DIR, ROOT, argument_parser, write_results
from tests.reference.bloom import unity_bloom
from torchgrade.testing.frames import edge_band_codes, turn_error, uniform_spread

COMMAND = ".venv/bin/python -m benchmarks bloom_frames --out benchmarks/results"
SIZES = [(512, 512), (37, 53), (61, 97), (333, 517), (644, 874), (720, 1280), (1080, 1920)]
MODES = {
    "additive": dict(mode="additive", intensity=1.0),
    "scattering": dict(mode="scattering", intensity=0.6, scatter=0.7),
    "energy_conserving": dict(mode="energy_conserving", intensity=0.6),
}
PHOTOGRAPHS = ("Desk", "Carrots", "CandleGlass", "GoldenGate", "Garden", "BrightRings", "WideColorGamut")


def bloom_of(settings):
    return lambda image: tg.functional.bloom(image, **settings)


def noise(height: int, width: int) -> torch.Tensor:
    generator = torch.Generator().manual_seed(0)
    image = torch.rand(1, 3, height, width, generator=generator) ** 3 * 4.0
    image[..., ::11, ::13] = 60.0
    return image


def uniform_rows() -> list:
    return [{"size": f"{h}x{w}", **{mode: uniform_spread(bloom_of(s), (1, 3, h, w), 8.0) for mode, s in MODES.items()}}
            for h, w in SIZES]


def turned_rows() -> list:
    return [{"size": f"{h}x{w}", **{mode: turn_error(bloom_of(s), noise(h, w), "turned") for mode, s in MODES.items()}}
            for h, w in SIZES]


def edge_rows() -> list:
    look = tg.PostFX.from_config(ROOT / "export" / "looks" / "cinematic.json").eval()
    rows = []
    for name in PHOTOGRAPHS:
        image = tg.io.read_exr(EXR_DIR / f"{name}.exr", to_rec709=True)[:3].unsqueeze(0)
        bands = edge_band_codes(lambda frame: look.frame(frame, None, 0.0)[0], image)
        rows.append({"photograph": name, "size": f"{image.shape[-2]}x{image.shape[-1]}", **bands})
    return rows


def light_rows() -> list:
    rows = []
    for h, w in [(37, 53), (333, 517), (1081, 1921)]:
        image = noise(h, w).double()
        out = tg.functional.bloom(image, mode="scattering", intensity=0.8, threshold=0.5)
        rows.append({"size": f"{h}x{w}", "light": float(out.sum() / image.sum() - 1)})
    return rows


def unity_rows() -> list:
    desk = tg.io.read_exr(EXR_DIR / "Desk.exr", to_rec709=True)[:3][None].double()
    desk = F.avg_pool2d(desk, 2)[0].permute(1, 2, 0).numpy()
    rows = []
    for size in [(256, 320), (255, 319), (101, 150), (37, 53)]:
        image = np.ascontiguousarray(desk[: size[0], : size[1]])
        for name, settings in [("additive", dict(mode="additive", fade_fireflies=False)),
                               ("additive, fireflies", dict(mode="additive")),
                               ("scattering", dict(mode="scattering", intensity=0.8, fade_fireflies=False))]:
            ours = tg.functional.bloom(torch.from_numpy(image).permute(2, 0, 1)[None], **settings)[0].permute(1, 2, 0).numpy()
            scattering = settings["mode"] == "scattering"
            row = {"size": f"{size[0]}x{size[1]}", "settings": name,
                   "light": float(ours.sum() / image.sum() - 1) if scattering else None}
            for address in ("mirror", "clamp"):
                expected = unity_bloom(image, address=address, **settings)
                row[f"{address} max"] = float(np.abs(ours - expected).max() / np.abs(expected - image).max())
                row[f"{address} light"] = float(expected.sum() / image.sum() - 1) if scattering else None
            rows.append(row)
    return rows


def table(rows: list, columns: list, formats: dict) -> list:
    lines = ["| " + " | ".join(columns) + " |", "| " + " | ".join("---" for _ in columns) + " |"]
    for row in rows:
        lines.append("| " + " | ".join("" if row[c] is None else formats.get(c, "{}").format(row[c]) for c in columns) + " |")
    return lines


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    torch.set_grad_enabled(False)
    report = {"uniform": uniform_rows(), "turned": turned_rows(), "edges": edge_rows(), "light": light_rows(),
              "unity": unity_rows()}
    percent = "{:.2%}"
    lines = ["# Bloom on whole frames", "", f"`{COMMAND}`. Not timed: measurements of pictures.", "",
             "## A uniform field of 8.0: (max - min) / mean of the output", ""]
    lines += table(report["uniform"], ["size", *MODES], {mode: percent for mode in MODES})
    lines += ["", "## A frame turned by 180°, bloomed and turned back: largest difference / largest glow", ""]
    lines += table(report["turned"], ["size", *MODES], {mode: "{:.1e}" for mode in MODES})
    lines += ["", "## The shipped look's 16-pixel edge bands against the turned render, 8-bit codes", ""]
    lines += table(report["edges"], ["photograph", "size", "left", "right", "top", "bottom"],
                   {band: "{:+.2f}" for band in ("left", "right", "top", "bottom")})
    lines += ["", "## Scattering's light, sum(out) / sum(in) - 1 (float64)", ""]
    lines += table(report["light"], ["size", "light"], {"light": "{:.1e}"})
    lines += ["", "## Unity's passes on Desk (half size, cropped): largest difference / largest glow, and the light",
              "", "`mirror`: Unity's passes with mirrored edges (torchgrade's rule); `clamp`: Unity's own. "
              "Light, of scattering: torchgrade's, then Unity's passes'.", ""]
    lines += table(report["unity"], ["size", "settings", "mirror max", "clamp max", "light", "mirror light", "clamp light"],
                   {"mirror max": percent, "clamp max": percent, "light": "{:+.1e}", "mirror light": "{:+.2%}",
                    "clamp light": "{:+.2%}"})
    write_results(args.out, "bloom_frames", report, lines, COMMAND)


if __name__ == "__main__":
    main()
