"""One LUT per look: ``tg.bake_lut(look)``, ``look.to_lut()`` and ``torchgrade bake`` build the same table from the same
arguments, and that table is the look evaluated in float64 on a lattice computed here from Unity's LogC formula."""

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg
from torchgrade.cli import main
from torchgrade.lut import LUTAccuracyWarning
from torchgrade.lut.shapers import SHAPERS

ROOT = Path(__file__).resolve().parents[2]
STATED_DEFAULT = re.compile(r"\b(\d+)³ by default|\bdefault (?:lattice |size )?(\d+)³|DEFAULT_SIZES`?: (\d+)")
"""How a page or a docstring states a default lattice size: ``51³ by default``, ``the default 39³``, ``DEFAULT_SIZES: 51``."""

LOOK = {"grade": {"contrast": 20.0, "saturation": 10.0, "temperature": 8.0}, "primary": {"saturation": 1.1},
        "tonemap": "aces"}
"""A look every door can bake: grade, primary grade and tone mapping, nothing live."""

A, B, C, D = 5.555556, 0.047996, 0.244161, 0.386036
"""Unity's LogC (ARRI Alexa, EI 800) constants, ColorGrading.hlsl ``LinearToLogC``: ``c log10(a x + b) + d``."""


def logc_decode(code: np.ndarray) -> np.ndarray:
    return (10.0 ** ((code - D) / C) - B) / A


def default_lattice_axis() -> np.ndarray:
    """The 51 linear values of the default lattice's planes, as its documentation defines it: shaper codes evenly
    spaced over the LUT's domain (LogC(0) to the code of 65504, stored as float32 numbers), LogC itself up to code 1
    (38 intervals), then segments linear in LogC codes: 6 intervals to LogC 1.3, 6 to LogC(65504)."""
    black, top_logc = C * np.log10(B) + D, C * np.log10(A * 65504.0 + B) + D
    step = (1.0 - black) / 38
    knots, codes_at = (1.0, 1.3, top_logc), (1.0, 1.0 + 6 * step, 1.0 + 12 * step)
    low, high = (float(np.float32(value)) for value in (black, codes_at[-1]))
    codes = low + np.arange(51) / 50 * (high - low)
    logc = np.where(codes <= codes_at[1], np.interp(codes, codes_at[:2], knots[:2]), np.interp(codes, codes_at[1:], knots[1:]))
    return logc_decode(np.where(codes <= 1.0, codes, logc))


def quiet(function, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        return function(*args, **kwargs)


@pytest.fixture(scope="module")
def doors(tmp_path_factory):
    """The look's table through each door, with every default: ``bake_lut``, ``to_lut``, and the command's ``.cube``."""
    folder = tmp_path_factory.mktemp("doors")
    look = tg.PostFX(**LOOK)
    (folder / "look.json").write_text(json.dumps(LOOK))
    assert main(["bake", "--config", str(folder / "look.json"), "-o", str(folder / "look.cube"), "--accept-error"]) == 0
    return {"look": look, "bake_lut": quiet(tg.bake_lut, look).table.detach(), "to_lut": quiet(look.to_lut).lut.table,
            "cube": tg.io.read_cube(folder / "look.cube").table}


def test_bake_lut_and_to_lut_build_the_same_table_at_the_one_default_size(doors):
    default = SHAPERS["logc_extended"].default_size
    assert doors["bake_lut"].shape == doors["to_lut"].shape == (default, default, default, 3)
    torch.testing.assert_close(doors["to_lut"].double(), doors["bake_lut"].double(), atol=1e-6, rtol=0)


def test_the_commands_cube_is_the_default_tables_planes_up_to_58_86(doors):
    size = SHAPERS["logc_extended"].cube_size
    assert doors["cube"].shape == (size, size, size, 3)
    torch.testing.assert_close(doors["cube"].double(), doors["bake_lut"][:size, :size, :size].double(), atol=1e-6, rtol=0)


def test_every_doors_table_is_the_look_in_float64_at_the_lattice_points(doors):
    """The table, clamped to [0, 1] as the lookup clamps it, against the look itself (its forward, the tone mapper's clip
    on) on float64 lattice points; table index ``[b, g, r]``."""
    axis = torch.from_numpy(default_lattice_axis())
    b, g, r = torch.meshgrid(axis, axis, axis, indexing="ij")
    points = torch.stack((r, g, b)).reshape(1, 3, 1, -1)
    with torch.no_grad():
        reference = doors["look"](points).reshape(3, *b.shape).permute(1, 2, 3, 0)
    assert reference.dtype == torch.float64
    size = SHAPERS["logc_extended"].cube_size
    for door, expected in (("bake_lut", reference), ("to_lut", reference), ("cube", reference[:size, :size, :size])):
        torch.testing.assert_close(doors[door].double().clamp(0, 1), expected, atol=1e-6, rtol=0)


def test_the_doors_agree_from_other_arguments_too():
    look = tg.PostFX(**LOOK)
    for arguments in ({"size": 17, "output_encoding": "srgb"}, {"size": 9, "entries": "fitted"}):
        baked, looked = quiet(tg.bake_lut, look, **arguments), quiet(look.to_lut, **arguments).lut
        torch.testing.assert_close(looked.table.double(), baked.table.detach().double(), atol=1e-6, rtol=0)
        assert looked.output_encoding == baked.output_encoding


def test_a_look_with_live_stages_is_baked_by_to_lut_and_refused_by_bake_lut():
    """Bloom cannot live in a LUT: ``to_lut`` keeps it live and bakes the rest, the same table ``bake_lut`` bakes of
    the look without it; ``bake_lut`` of the whole look says what it cannot hold."""
    with_bloom = tg.PostFX(bloom={"intensity": 0.5}, **LOOK)
    baked = quiet(with_bloom.to_lut, 9)
    assert baked.bloom is not None and baked.lut is not None
    torch.testing.assert_close(baked.lut.table.double(), quiet(tg.bake_lut, tg.PostFX(**LOOK), size=9).table.detach(),
                               atol=1e-6, rtol=0)
    with pytest.raises(ValueError, match="bloom, which a LUT cannot hold: look.to_lut()"):
        tg.bake_lut(with_bloom, size=9)


def test_the_doors_report_the_same_figures_on_the_same_frames():
    look = tg.PostFX(**LOOK)
    frames = tg.scene.demo_scene(40, 60)
    reports = [quiet(tg.bake_lut, look, size=9, frames=frames).error_report,
               quiet(look.to_lut, 9, frames=frames).lut.error_report]
    assert reports[0].colour_set == reports[1].colour_set == "pixels of the given frames"
    assert (reports[0].p99_9, reports[0].max, reports[0].colours) == (reports[1].p99_9, reports[1].max, reports[1].colours)


def stated_defaults(path: Path) -> list:
    return [int(next(size for size in match.groups() if size)) for match in STATED_DEFAULT.finditer(path.read_text(encoding="utf-8"))]


def test_the_default_size_is_stated_once_in_the_docs_and_as_the_constant_everywhere():
    """The pages (README and docs/) state the bake's default size once; every page or docstring that states a default
    size states the constant: ``logc_extended``'s ``default_size`` for the bake, its ``cube_size`` for the ``.cube``
    the command writes."""
    shaper = SHAPERS["logc_extended"]
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    stated = {path.relative_to(ROOT).as_posix(): stated_defaults(path)
              for path in [*pages, *sorted((ROOT / "torchgrade").rglob("*.py"))]}
    assert {size for sizes in stated.values() for size in sizes} == {shaper.default_size, shaper.cube_size}
    assert [name for name, sizes in stated.items() for size in sizes if size == shaper.default_size and name.endswith(".md")] \
        == ["docs/lut.md"]
