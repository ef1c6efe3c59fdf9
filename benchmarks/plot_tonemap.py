"""Tone mapping figures and the distance of the ACES modes to OpenColorIO on every pixel of the sample images.

* ``tonemap_curves.png``: every SDR mode's grey curve (sRGB-encoded display value against scene stops
  around mid grey) and the HDR modes' curves in cd/m² for a 1000 cd/m² display.
* ``tonemap_aces1_vs_aces2.png``: ``aces_reference`` (ACES 1.0.3) and ``aces2`` (ACES 2.0) on two sample images.
* ``tonemap_distance.json`` / ``.md``: for the modes OpenColorIO implements, the largest and p99.9 distance
  in display codes on every finite pixel of every top-level sample image (exposed so the median positive
  Rec.709 luminance is 0.18; pixels beyond ±65504, which the library's non-finite policy bounds, left out).

Run: ``.venv/bin/python -m benchmarks tonemap [--skip-distance] [--out DIR]`` (writes to ``--out``, default
benchmarks/out; the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch

import torchgrade as tg
from benchmarks.common import EXR_DIR, argument_parser, write_results
from torchgrade.functional import tonemap

ROOT = Path(__file__).resolve().parents[1]

COMMAND = ".venv/bin/python -m benchmarks tonemap"
HDR_MODES = {"aces2_hdr": dict(peak_luminance=1000.0), "neutral_hdr": dict(peak_luminance=1000.0)}
# mode -> (OpenColorIO config, display, view, encoding of our display-linear output, code scale)
OCIO_VIEWS = {
    "aces_reference (sRGB)": ("studio-config-v2.2.0_aces-v1.3_ocio-v2.4", "sRGB - Display", "ACES 1.0 - SDR Video", "srgb", 255),
    "aces_reference (BT.1886)": ("studio-config-v2.2.0_aces-v1.3_ocio-v2.4", "Rec.1886 Rec.709 - Display", "ACES 1.0 - SDR Video", "bt1886", 255),
    "aces2": ("studio-config-v4.0.0_aces-v2.0_ocio-v2.5", "Rec.1886 Rec.709 - Display", "ACES 2.0 - SDR 100 nits (Rec.709)", "bt1886", 255),
    "aces2_hdr": ("studio-config-v4.0.0_aces-v2.0_ocio-v2.5", "Rec.2100-PQ - Display", "ACES 2.0 - HDR 1000 nits (P3 D65)", "pq", 1023),
}


def greys(stops: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(0.18 * 2.0**stops).double().reshape(1, 1, 1, -1).expand(1, 3, 1, -1)


def plot_curves(path: Path) -> None:
    """Fifteen SDR curves need fifteen looks: each mode its own colour (tab20) and a line style per family, the
    legend beside the axes rather than over the curves' toes."""
    stops = np.linspace(-10, 12, 400)
    figure, (sdr, hdr) = plt.subplots(1, 2, figsize=(15, 5.5), gridspec_kw={"width_ratios": [1.25, 1]})
    sdr_modes = [mode for mode in tg.TONEMAP_MODES if mode not in HDR_MODES and mode != "none"]
    colours, styles = plt.get_cmap("tab20").colors, ("-", "--", "-.", ":")
    for index, mode in enumerate(sdr_modes):
        out = tg.color.linear_to_srgb(tonemap(greys(stops), mode))[0, 1, 0].numpy()
        sdr.plot(stops, out, label=mode, color=colours[index % len(colours)], ls=styles[index % len(styles)],
                 lw=2.4 if mode in ("aces_reference", "aces2") else 1.4)
    sdr.set(xlabel="scene exposure (stops above 0.18)", ylabel="sRGB-encoded display value (0..1)", title="SDR modes, grey ramp")
    sdr.set_xlim(stops[0], stops[-1])
    sdr.grid(alpha=0.3)
    sdr.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), title="mode", title_fontsize=9)
    floor = 1e-3
    for mode, settings in HDR_MODES.items():
        nits = tonemap(greys(stops), mode, **settings)[0, 1, 0].numpy() * settings["peak_luminance"]
        hdr.semilogy(stops, np.maximum(nits, floor), label=f"{mode}, 1000 cd/m² peak")
    sdr_nits = tonemap(greys(stops), "aces2")[0, 1, 0].numpy() * 100.0
    hdr.semilogy(stops, np.maximum(sdr_nits, floor), "--", label="aces2 (SDR, 100 cd/m² peak)")
    hdr.set(xlabel="scene exposure (stops above 0.18)", ylabel="display luminance (cd/m², log scale)",
            title=f"HDR modes, grey ramp (below {floor:g} cd/m² drawn at {floor:g})")
    hdr.grid(alpha=0.3, which="both")
    hdr.legend(fontsize=8, loc="upper left")
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def exposed(name: str) -> torch.Tensor:
    image = tg.io.read_exr(EXR_DIR / f"{name}.exr", to_rec709=True)[:3]
    y = (image * torch.tensor([0.2126729, 0.7151522, 0.0721750]).reshape(3, 1, 1)).sum(0)
    return image * (0.18 / y[(y > 0) & y.isfinite()].median())


def plot_aces1_vs_aces2(path: Path, names=("CandleGlass", "WideColorGamut")) -> None:
    figure, axes = plt.subplots(len(names), 2, figsize=(10, 4.2 * len(names)))
    for row, name in zip(axes, names):
        image = exposed(name)[None, :, ::2, ::2]
        for axis, mode in zip(row, ("aces_reference", "aces2")):
            shown = tg.color.linear_to_srgb(tonemap(image, mode))[0].permute(1, 2, 0).numpy()
            axis.imshow(np.clip(shown, 0, 1))
            axis.set_title(f"{name}: {mode}", fontsize=9)
            axis.axis("off")
    figure.tight_layout()
    figure.savefig(path, dpi=90)


def _ocio(config: str, display: str, view: str, rgb: np.ndarray) -> np.ndarray:
    import PyOpenColorIO as OCIO

    processor = OCIO.Config.CreateFromBuiltinConfig(config).getProcessor("Linear Rec.709 (sRGB)", display, view, OCIO.TRANSFORM_DIR_FORWARD)
    out = np.ascontiguousarray(rgb, dtype=np.float32).copy()
    processor.getDefaultCPUProcessor().applyRGB(out)
    return np.clip(out, 0.0, 1.0)


def _ours(label: str, encoding: str, rgb: np.ndarray) -> np.ndarray:
    mode = label.split(" ")[0]
    image = torch.from_numpy(np.ascontiguousarray(rgb.T))[None, :, :, None]
    with torch.no_grad():
        linear = torch.cat([tonemap(part, mode) for part in image.split(1 << 18, dim=2)], dim=2)
    encoded = tg.output.display.encode_display(linear, encoding, "rec2020", 1000.0, "rec2020") if encoding == "pq" else \
        tg.output.display.encode_display(linear, encoding)
    return encoded[0, :, :, 0].T.double().numpy()


def distances() -> dict:
    result = {}
    for path in sorted(EXR_DIR.glob("*.exr")):
        rgb = exposed(path.stem).reshape(3, -1).T.numpy()
        rgb = rgb[np.isfinite(rgb).all(1) & (np.abs(rgb) <= 65504).all(1)].astype(np.float32)
        for label, (config, display, view, encoding, scale) in OCIO_VIEWS.items():
            d = np.abs(_ours(label, encoding, rgb) - _ocio(config, display, view, rgb)) * scale
            result.setdefault(label, {})[path.stem] = {"pixels": len(rgb), "max": round(float(d.max()), 3),
                                                       "p999": round(float(np.percentile(d, 99.9)), 3)}
            print(label, path.stem, result[label][path.stem], flush=True)
    return result


def markdown(result: dict) -> str:
    names = sorted(next(iter(result.values())))
    lines = ["Distance to OpenColorIO 2.6 on every pixel, in display codes (8-bit; 10-bit for PQ): max / p99.9.", "",
             "| mode (encoding) | " + " | ".join(names) + " |", "| --- |" + " --- |" * len(names)]
    for label, per_image in result.items():
        lines.append(f"| {label} | " + " | ".join(f"{per_image[n]['max']} / {per_image[n]['p999']}" for n in names) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--skip-distance", action="store_true", help="only the plots, not the distance to OpenColorIO")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    plot_curves(args.out / "tonemap_curves.png")
    plot_aces1_vs_aces2(args.out / "tonemap_aces1_vs_aces2.png")
    if not args.skip_distance:
        measured = distances()
        write_results(args.out, "tonemap_distance", measured, markdown(measured).splitlines(), COMMAND)


if __name__ == "__main__":
    main()
