"""Every sample image through the shipped look: a contact sheet and a table of what the look does to each.

Usage::

    .venv/bin/python -m benchmarks exposure_samples [--look export/looks/cinematic.json] [--out DIR]

For every image of ``../shared/data/exr`` (and ``formats/``; a deep file holds no flat image and is listed as
such) the table gives the exposure the look's eye adaptation applies, in stops from viewing the file as it
was authored (``AutoExposure.exposure_stops``, compensation and curve included; the grade's ``post_exposure``
adds its own), and the median, 5th and 95th percentiles of display luminance (Rec.709 luminance of the
display-referred output, sRGB-encoded) as authored (ACES at exposure 0) and through the look.

**The rule** (:func:`verdict`): the anchors' histogram meters put the average of the 40-90 % band of a frame on
middle grey, and a compensation curve keeps dark scenes dark (Bevy, Unreal); what a frame may not lose is its
shadows or its highlights. With ``grey`` the display luminance the look gives a uniform middle-grey frame:

* washed out: the 5th percentile above one stop over ``grey`` (``2 * grey`` in linear display light): even the
  darkest twentieth of the frame sits well above middle grey, so the frame holds no shadows;
* crushed: the 95th percentile below one stop under ``grey``: even the brightest twentieth sits well below
  middle grey, so the frame holds no highlights.

A frame that is only shadows or only highlights (a uniform chart) sits at ``grey`` and passes, as a meter
should leave it. ``tests/exposure/test_exposure_samples.py`` applies the rule to every sample image, so a new image or
a new default is judged the same way. Writes ``exposure_samples.md`` and ``exposure_samples.jpg`` to ``--out``
(default benchmarks/out; the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

import torchgrade as tg
from torchgrade.color import linear_to_srgb, luminance
from torchgrade.io import read_exr
from torchgrade.io.atomic import atomic_write
from benchmarks.common import argument_parser, write_markdown

ROOT = Path(__file__).resolve().parents[1]

SAMPLES = ROOT.parent / "shared" / "data" / "exr"
LOOK = ROOT / "export" / "looks" / "cinematic.json"
TILE = 200
"""Width of a contact-sheet tile, pixels."""


def sample_paths() -> list:
    """Every sample EXR: the top folder and ``formats/`` (not ``damaged/``), sorted."""
    return sorted(SAMPLES.glob("*.exr")) + sorted((SAMPLES / "formats").glob("*.exr"))


def read_sample(path: Path):
    """``(1, 3, H, W)`` linear Rec.709 of a sample, or the reason it holds no flat image."""
    try:
        return read_exr(path, to_rec709=True, adaptation="auto")[:3].unsqueeze(0)
    except ValueError as error:
        if "deep" in str(error):
            return "deep data: no flat image"
        raise


@dataclass(frozen=True)
class Display:
    """Percentiles of a frame's display luminance, sRGB-encoded."""

    p5: float
    median: float
    p95: float


def display_statistics(display: torch.Tensor) -> Display:
    """:class:`Display` of a display-referred ``(1, 3, H, W)`` frame (clamped to [0, 1] as a display shows it)."""
    signal = linear_to_srgb(luminance(display.clamp(0, 1)).clamp(0, 1)).flatten().double().numpy()
    p5, median, p95 = np.percentile(signal, [5, 50, 95])
    return Display(float(p5), float(median), float(p95))


def middle_grey_display(look: tg.PostFX) -> float:
    """The display luminance the look gives a uniform middle-grey frame, linear."""
    with torch.no_grad():
        return float(luminance(look(torch.full((1, 3, 8, 8), 0.18)).clamp(0, 1)).mean())


def verdict(statistics: Display, grey: float) -> str:
    """``"washed out"``, ``"crushed"`` or ``"ok"`` by the module's rule; ``grey`` from :func:`middle_grey_display`."""
    if statistics.p5 > float(linear_to_srgb(torch.tensor(min(2 * grey, 1.0)))):
        return "washed out"
    if statistics.p95 < float(linear_to_srgb(torch.tensor(grey / 2))):
        return "crushed"
    return "ok"


def as_authored(image: torch.Tensor) -> torch.Tensor:
    """The file viewed as authored: ACES tone mapping at exposure 0."""
    return tg.ToneMap("aces")(image)


def through_look(look: tg.PostFX, image: torch.Tensor) -> tuple:
    """The look's display frame and the stops its eye adaptation applies (0 without one)."""
    if look.exposure is None:
        return look(image), 0.0
    display, adapted = look.frame(image, None, 0.0)
    return display, float(look.exposure.exposure_stops(adapted)[0])


def contact_sheet(rows: list, path: Path) -> None:
    """Write ``(name, before, after)`` display frames as a two-column JPEG, atomically."""
    from PIL import Image, ImageDraw

    from torchgrade.cli.common import display_codes

    tiles = []
    for name, before, after in rows:
        pair = [Image.fromarray(display_codes(frame[0], 255).astype(np.uint8)) for frame in (before, after)]
        height = round(TILE * pair[0].height / pair[0].width)
        tiles.append((name, [tile.resize((TILE, height), Image.LANCZOS) for tile in pair]))
    label = 14
    sheet = Image.new("RGB", (2 * TILE + 4, sum(tile[0].height + label + 4 for _, tile in tiles) + label), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    draw.text((4, 0), "as authored (ACES, exposure 0)", fill=(220, 220, 220))
    draw.text((TILE + 8, 0), "through the look", fill=(220, 220, 220))
    top = label
    for name, (before, after) in tiles:
        draw.text((4, top), name, fill=(220, 220, 220))
        sheet.paste(before, (0, top + label))
        sheet.paste(after, (TILE + 4, top + label))
        top += before.height + label + 4
    atomic_write(path, lambda temporary: sheet.save(temporary, format="JPEG", quality=85, optimize=True))


def main(argv=None) -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--look", default=str(LOOK), help="look JSON (default export/looks/cinematic.json)")
    args = parser.parse_args(argv)
    look = tg.PostFX.from_config(json.loads(Path(args.look).read_text())).eval()
    grey = middle_grey_display(look)
    lines = [f"# Every sample image through `{Path(args.look).relative_to(ROOT) if Path(args.look).is_relative_to(ROOT) else args.look}`", "",
             f"Command: `.venv/bin/python -m benchmarks exposure_samples`. Display luminance: Rec.709 luminance "
             f"of the display frame, sRGB-encoded. The look shows middle grey at {float(linear_to_srgb(torch.tensor(grey))):.2f}; "
             f"washed out: 5th percentile above {float(linear_to_srgb(torch.tensor(min(2 * grey, 1.0)))):.2f}, crushed: 95th "
             f"percentile below {float(linear_to_srgb(torch.tensor(grey / 2))):.2f} (one stop either side of it).", "",
             "| image | size | exposure (stops) | as authored p5 / median / p95 | look p5 / median / p95 | verdict |",
             "|---|---|---:|---|---|---|"]
    rows = []
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        for path in sample_paths():
            image = read_sample(path)
            name = str(path.relative_to(SAMPLES))
            if isinstance(image, str):
                lines.append(f"| {name} | | | {image} | | |")
                continue
            before = as_authored(image)
            after, stops = through_look(look, image)
            b, a = display_statistics(before), display_statistics(after)
            lines.append(f"| {name} | {image.shape[-1]}x{image.shape[-2]} | {stops:+.2f} | {b.p5:.2f} / {b.median:.2f} / {b.p95:.2f} | "
                         f"{a.p5:.2f} / {a.median:.2f} / {a.p95:.2f} | {verdict(a, grey)} |")
            rows.append((name, before, after))
    lines += ["", "![Contact sheet](exposure_samples.jpg)", ""]
    write_markdown(args.out, "exposure_samples.md", lines)
    contact_sheet(rows, args.out / "exposure_samples.jpg")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
