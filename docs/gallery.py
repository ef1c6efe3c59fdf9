"""The pictures of ``docs/gallery.md``: every SDR tone mapper and every shipped look on a few sample EXRs.

    .venv/bin/python docs/gallery.py                      # writes build/gallery/ (not committed)
    .venv/bin/python docs/gallery.py --out docs/gallery   # rewrites the committed pictures

One contact sheet per image (``tonemappers-<image>.jpg``: the modes of ``tg.TONEMAP_MODES`` less the HDR ones, which
give Rec.2020 light for a brighter display than a JPEG shows) and one per look (``look-<name>.jpg``:
``export/looks/<name>.json`` on each image). For the tone mappers each image is exposed so its median positive
Rec.709 luminance is 0.18, as ``benchmarks/plot_tonemap.py`` measures them; a look takes the file as read, its own
eye adaptation exposing it (adapted at once, as a still). The linear light is averaged down to twice the tile width
before the look (a tile is ``--tile`` pixels wide, 320 by default), then the display image is resampled to the tile.

Every frame is checked whole before its sheet is written (:func:`torchgrade.testing.frames.edge_band_codes`): a frame
whose 16-pixel edge band differs from the same frame rendered turned by 180° and turned back by more than
:data:`EDGE_CODES` 8-bit codes (a glowing or darkened border) stops the script, and no sheet is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

import torchgrade as tg
from torchgrade.cli.common import display_codes
from torchgrade.testing.frames import edge_band_codes

ROOT = Path(__file__).resolve().parents[1]
IMAGES = ("Desk", "CandleGlass", "GoldenGate")
SDR_MODES = tuple(mode for mode in tg.TONEMAP_MODES if mode not in tg.tonemap.HDR_MODES)
LOOKS = tuple(sorted(path.stem for path in (ROOT / "export" / "looks").glob("*.json")))
COLUMNS = 4
EDGE_CODES = 2.0
"""Largest difference, in 8-bit codes, between a frame's edge band and the turned render's that a sheet may show."""
LABEL = 14
BACKGROUND = (24, 24, 24)
TEXT = (220, 220, 220)


def sheet_names(images=IMAGES, looks=LOOKS) -> list:
    """The file names :func:`main` writes for ``images`` and ``looks``."""
    return [f"tonemappers-{image}.jpg" for image in images] + [f"look-{look}.jpg" for look in looks]


def read(exr_dir: Path, name: str, width: int) -> torch.Tensor:
    """``(1, 3, H, W)`` linear Rec.709 of a sample, its light averaged down to ``width`` pixels wide."""
    image = tg.io.read_exr(exr_dir / f"{name}.exr", to_rec709=True)[:3].unsqueeze(0)
    height = max(1, round(image.shape[-2] * width / image.shape[-1]))
    return F.interpolate(image, size=(height, width), mode="area") if width < image.shape[-1] else image


def exposed(image: torch.Tensor) -> torch.Tensor:
    """``image`` scaled so its median positive Rec.709 luminance is 0.18."""
    y = tg.color.luminance(image)
    return image * (0.18 / y[(y > 0) & y.isfinite()].median())


def tile(display: torch.Tensor, width: int):
    """A display-referred linear ``(1, 3, H, W)`` frame as an sRGB picture ``width`` pixels wide."""
    from PIL import Image

    picture = Image.fromarray(display_codes(display[0], 255).astype(np.uint8))
    return picture.resize((width, round(picture.height * width / picture.width)), Image.LANCZOS)


def contact_sheet(title: str, tiles: list, path: Path, quality: int) -> None:
    """``(label, picture)`` tiles in rows of :data:`COLUMNS`, under ``title``, as a JPEG."""
    from PIL import Image, ImageDraw

    width, height = max(picture.width for _, picture in tiles), max(picture.height for _, picture in tiles)
    columns = min(COLUMNS, len(tiles))
    rows = -(-len(tiles) // columns)
    sheet = Image.new("RGB", (columns * (width + 4), LABEL + rows * (height + LABEL + 4)), BACKGROUND)
    draw = ImageDraw.Draw(sheet)
    draw.text((4, 0), title, fill=TEXT)
    for index, (label, picture) in enumerate(tiles):
        left, top = (index % columns) * (width + 4), LABEL + (index // columns) * (height + LABEL + 4)
        draw.text((left + 4, top), label, fill=TEXT)
        sheet.paste(picture, (left, top + LABEL))
    sheet.save(path, format="JPEG", quality=quality, optimize=True)


class EdgeCheckError(SystemExit):
    """A frame of a sheet failed the edge check: the message names it and its bands."""


def checked(render, image: torch.Tensor, label: str) -> torch.Tensor:
    """``render(image)``, after checking that its edge bands match the turned render's within :data:`EDGE_CODES`.

    Raises :class:`EdgeCheckError` (exit status 1, the bands in codes) for a frame that fails.
    """
    bands = edge_band_codes(render, image)
    worst = max(bands, key=lambda band: abs(bands[band]))
    if abs(bands[worst]) > EDGE_CODES:
        codes = ", ".join(f"{band} {value:+.1f}" for band, value in bands.items())
        raise EdgeCheckError(f"{label}: the {worst} edge differs from the frame rendered turned by 180° by "
                             f"{bands[worst]:+.1f} 8-bit codes ({codes}; at most {EDGE_CODES:g}); no sheet written")
    return render(image)


def through_look(look: tg.PostFX, image: torch.Tensor) -> torch.Tensor:
    """The look's display frame of a still: its eye adaptation, if any, adapted at once."""
    if look.exposure is None:
        return look(exposed(image))
    return look.frame(image, None, 0.0)[0]


def main(argv=None) -> list:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "gallery",
                        help="folder to write (default build/gallery; docs/gallery holds the committed pictures)")
    parser.add_argument("--exr-dir", type=Path, default=ROOT.parent / "shared" / "data" / "exr")
    parser.add_argument("--images", nargs="+", default=list(IMAGES), help="sample EXR names (default: %(default)s)")
    parser.add_argument("--modes", nargs="+", default=list(SDR_MODES), choices=SDR_MODES, metavar="MODE",
                        help="tone mappers of the sheets (default: every SDR mode)")
    parser.add_argument("--tile", type=int, default=320, help="tile width in pixels")
    parser.add_argument("--quality", type=int, default=80, help="JPEG quality")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    images = {name: read(args.exr_dir, name, 2 * args.tile) for name in args.images}
    sheets = []  # (title, tiles, path): every frame is rendered and checked before any sheet is written
    with torch.no_grad():
        for name, image in images.items():
            scene = exposed(image)
            tiles = [(mode, tile(checked(tg.ToneMap(mode), scene, f"{name} through {mode}"), args.tile)) for mode in args.modes]
            sheets.append((f"{name}, exposed to a median of 0.18, through each SDR tone mapper", tiles, args.out / f"tonemappers-{name}.jpg"))
        for look_name in LOOKS:
            look = tg.PostFX.from_config(ROOT / "export" / "looks" / f"{look_name}.json")
            render = lambda image, look=look: through_look(look, image)  # noqa: E731
            tiles = [(name, tile(checked(render, image, f"{look_name} on {name}"), args.tile)) for name, image in images.items()]
            sheets.append((f"export/looks/{look_name}.json", tiles, args.out / f"look-{look_name}.jpg"))
    written = []
    for title, tiles, path in sheets:
        contact_sheet(title, tiles, path, args.quality)
        written.append(path)
    for path in written:
        print(f"{path}  {path.stat().st_size / 1024:.0f} KiB")
    return written


if __name__ == "__main__":
    main()
