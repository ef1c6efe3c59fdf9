""".cube interchange: exact round trips, both directions against OpenColorIO, strict parsing."""

import itertools

import numpy as np
import pytest
import torch

PyOpenColorIO = pytest.importorskip("PyOpenColorIO")
OCIO = PyOpenColorIO

from torchgrade.io.cube import read_cube, write_cube  # noqa: E402
from torchgrade.lut import LUT3D, bake_lut, identity_table  # noqa: E402

_names = itertools.count()
OCIO_INTERPOLATION = {"tetrahedral": OCIO.INTERP_TETRAHEDRAL, "trilinear": OCIO.INTERP_LINEAR}


def look(image: torch.Tensor) -> torch.Tensor:
    """Cross-talk and a compressive curve: enough structure that a wrong lattice order shows."""
    r, g, b = image.unbind(-3)
    y = torch.stack((0.9 * r + 0.1 * g, g + 0.05 * b, 1.1 * b + 0.05 * r), dim=-3).clamp_min(0.0)
    return y / (1.0 + y)


def unique_cube(folder) -> str:
    """A fresh file name per LUT: OpenColorIO caches file transforms by path."""
    return str(folder / f"lut{next(_names)}.cube")


def ocio_apply(path: str, image: torch.Tensor, interpolation: str) -> torch.Tensor:
    config = OCIO.Config.CreateRaw()
    transform = OCIO.FileTransform(src=path, interpolation=OCIO_INTERPOLATION[interpolation])
    processor = config.getProcessor(transform).getDefaultCPUProcessor()
    pixels = np.ascontiguousarray(image[0].permute(1, 2, 0).numpy().astype(np.float32))
    processor.applyRGB(pixels)
    return torch.from_numpy(pixels).permute(2, 0, 1).unsqueeze(0)


def hdr_image() -> torch.Tensor:
    return torch.exp(torch.randn(1, 3, 32, 32) * 2.0 - 1.0)


@pytest.mark.parametrize("shaper", ["linear", "logc"])
def test_round_trip_keeps_the_table_bit_exact(tmp_path, shaper):
    lut = bake_lut(look, size=9, shaper=shaper)
    path = unique_cube(tmp_path)
    write_cube(path, lut)
    back = read_cube(path)
    assert torch.equal(back.table, lut.table.float())
    image = hdr_image()
    tolerance = 0 if shaper == "linear" else 1e-4  # the LogC shaper travels as a 65536-point 1D table
    torch.testing.assert_close(back(image), lut(image), atol=tolerance, rtol=0)


@pytest.mark.parametrize("interpolation", ["tetrahedral", "trilinear"])
def test_the_logc_hdr_tail_does_not_fit_a_cube_section_so_the_file_clamps_at_58_86(tmp_path, interpolation):
    """A 1D section samples evenly in linear values: the file holds LogC up to 58.86 (its 65536 points 0.0009 apart)
    and clamps each channel above it, as a "logc" LUT's file does; OpenColorIO and read_cube agree on it."""
    from torchgrade.lut.shapers import LOGC_TOP

    lut = bake_lut(look, size=17, shaper="logc_hdr")
    path = unique_cube(tmp_path)
    write_cube(path, lut)
    lines = open(path).read().splitlines()
    assert float(lines[2].split()[2]) == pytest.approx(58.8566, abs=1e-4)  # LUT_1D_INPUT_RANGE low high
    image = hdr_image() * 10.0
    assert bool((image > LOGC_TOP).any())
    back = read_cube(path)
    torch.testing.assert_close(back(image, interpolation), lut(image.clamp(max=LOGC_TOP), interpolation), atol=1e-4, rtol=0)
    torch.testing.assert_close(ocio_apply(path, image, interpolation), back(image, interpolation), atol=1e-5, rtol=0)


def test_srgb_encoded_lut_is_written_with_linear_entries(tmp_path):
    from torchgrade.tonemap import ToneMap

    lut = bake_lut(ToneMap("reinhard"), size=9, shaper="linear", output_encoding="srgb")
    assert lut.output_encoding == "srgb"
    path = unique_cube(tmp_path)
    write_cube(path, lut)
    back = read_cube(path)
    torch.testing.assert_close(back.table, lut.linear_table().float(), atol=1e-6, rtol=0)
    image = torch.rand(1, 3, 16, 16)
    assert torch.equal(back(image, "trilinear").clamp(0, 1), back(image, "trilinear"))


def test_identity_lut_round_trips_exactly_on_lattice_points(tmp_path):
    path = unique_cube(tmp_path)
    write_cube(path, LUT3D(identity_table(17)))
    axis = torch.linspace(0, 1, 17)
    points = torch.stack(torch.meshgrid(axis, axis, axis, indexing="ij")).reshape(1, 3, -1, 1)
    assert torch.equal(read_cube(path)(points), points)


def test_written_file_follows_the_conventions(tmp_path):
    path = unique_cube(tmp_path)
    table = torch.zeros(2, 2, 2, 3)
    table[0, 0, 1] = torch.tensor([1.0, 0.0, 0.0])  # red = 1 is the second row: red varies fastest
    write_cube(path, LUT3D(table, domain=(0.0, 2.0)), title="look")
    lines = open(path).read().splitlines()
    assert lines[:4] == ['TITLE "look"', "DOMAIN_MIN 0.0 0.0 0.0", "DOMAIN_MAX 2.0 2.0 2.0", "LUT_3D_SIZE 2"]
    assert lines[4:6] == ["0 0 0", "1 0 0"]


@pytest.mark.parametrize("interpolation", ["tetrahedral", "trilinear"])
@pytest.mark.parametrize("shaper", ["linear", "logc"])
def test_opencolorio_applies_our_cube_like_lut3d(tmp_path, shaper, interpolation):
    lut = bake_lut(look, size=17, shaper=shaper)
    path = unique_cube(tmp_path)
    write_cube(path, lut)
    image = hdr_image()
    torch.testing.assert_close(lut(image, interpolation), ocio_apply(path, image, interpolation), atol=1e-4, rtol=0)


def _baked_by_opencolorio(folder, file_format: str, shaper: bool) -> str:
    """Bake a saturation + exponent look with OpenColorIO's Baker (optionally with a log shaper)."""
    config = OCIO.Config.CreateRaw()
    config.addColorSpace(OCIO.ColorSpace(name="linear"))  # "raw" is a data space: nothing converts from it
    graded = OCIO.ColorSpace(name="graded")
    group = OCIO.GroupTransform()
    group.appendTransform(OCIO.CDLTransform(slope=[1.1, 1.0, 0.9], offset=[0.01, 0.0, -0.01], power=[1.2, 1.0, 0.8], sat=1.3))
    graded.setTransform(group, OCIO.COLORSPACE_DIR_FROM_REFERENCE)
    config.addColorSpace(graded)
    log = OCIO.ColorSpace(name="log")
    log.setTransform(OCIO.LogAffineTransform(logSideSlope=[0.1] * 3, logSideOffset=[0.5] * 3, linSideOffset=[0.05] * 3), OCIO.COLORSPACE_DIR_FROM_REFERENCE)
    config.addColorSpace(log)
    baker = OCIO.Baker()
    baker.setConfig(config)
    baker.setFormat(file_format)
    baker.setInputSpace("linear")
    baker.setTargetSpace("graded")
    baker.setCubeSize(17)
    if shaper:
        baker.setShaperSpace("log")
        baker.setShaperSize(1024)
    path = unique_cube(folder)
    with open(path, "w") as handle:
        handle.write(baker.bake())
    return path


@pytest.mark.parametrize("interpolation", ["tetrahedral", "trilinear"])
@pytest.mark.parametrize("file_format, shaper", [("iridas_cube", False), ("resolve_cube", True)])
def test_we_apply_opencolorio_baked_cubes_like_opencolorio(tmp_path, file_format, shaper, interpolation):
    path = _baked_by_opencolorio(tmp_path, file_format, shaper)
    lut = read_cube(path)
    assert lut.shaper == ("curve" if shaper else "linear")
    assert (lut.table - identity_table(17)).abs().max() > 0.05  # a real look, not an identity
    image = torch.rand(1, 3, 32, 32) * (4.0 if shaper else 1.2) - 0.1
    torch.testing.assert_close(lut(image, interpolation), ocio_apply(path, image, interpolation), atol=1e-4, rtol=0)


def _table_rows(size: int) -> str:
    return "\n".join("0.5 0.25 0.125" for _ in range(size**3)) + "\n"


MALFORMED = {
    "no size": "TITLE \"x\"\n" + _table_rows(2),
    "size too small": "LUT_3D_SIZE 1\n0 0 0\n",
    "size too large": "LUT_3D_SIZE 100000\n0 0 0\n",
    "size not an integer": "LUT_3D_SIZE 2.5\n" + _table_rows(2),
    "truncated": "LUT_3D_SIZE 3\n" + "\n".join(_table_rows(3).splitlines()[:20]) + "\n",
    "too many rows": "LUT_3D_SIZE 2\n" + _table_rows(2) + "0 0 0\n",
    "two numbers on a row": "LUT_3D_SIZE 2\n" + _table_rows(2).replace("0.5 0.25 0.125", "0.5 0.25", 1),
    "nan": "LUT_3D_SIZE 2\n" + _table_rows(2).replace("0.5 0.25 0.125", "nan 0 0", 1),
    "inf": "LUT_3D_SIZE 2\n" + _table_rows(2).replace("0.5 0.25 0.125", "0 inf 0", 1),
    "text in data": "LUT_3D_SIZE 2\n" + _table_rows(2).replace("0.5 0.25 0.125", "0 zero 0", 1),
    "unknown keyword": "LUT_3D_SIZE 2\nGAMMA 2.2\n" + _table_rows(2),
    "duplicate keyword": "LUT_3D_SIZE 2\nLUT_3D_SIZE 2\n" + _table_rows(2),
    "empty domain": "DOMAIN_MIN 1 0 0\nDOMAIN_MAX 1 1 1\nLUT_3D_SIZE 2\n" + _table_rows(2),
    "non-finite domain": "DOMAIN_MIN 0 0 0\nDOMAIN_MAX inf 1 1\nLUT_3D_SIZE 2\n" + _table_rows(2),
    "shaper too large": "LUT_1D_SIZE 10000000\nLUT_3D_SIZE 2\n" + _table_rows(2),
    "1D only, truncated": "LUT_1D_SIZE 3\n0 0 0\n1 1 1\n",
    "empty": "",
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_malformed_files_raise_value_error(tmp_path, name):
    path = tmp_path / "bad.cube"
    path.write_text(MALFORMED[name])
    with pytest.raises(ValueError):
        read_cube(path)


def test_binary_garbage_raises_value_error(tmp_path):
    path = tmp_path / "bad.cube"
    path.write_bytes(b"LUT_3D_SIZE 2\n\xff\xfe\x00garbage\n")
    with pytest.raises(ValueError, match="not a text file"):
        read_cube(path)


def test_absurdly_large_file_is_refused_before_reading(tmp_path):
    path = tmp_path / "huge.cube"
    with open(path, "wb") as handle:
        handle.write(b"LUT_3D_SIZE 2\n0 0 0\n")
        handle.truncate(8 << 30)  # a sparse 8 GiB file: reading it would exhaust memory
    with pytest.raises(ValueError, match="larger than"):  # than the largest table's file, before it is opened
        read_cube(path)
    path.write_bytes(b"LUT_3D_SIZE 2\n" + b"0 0 0\n" * 8 + b"# a comment\n" * (1 << 18))  # 3 MiB: within that
    with pytest.raises(ValueError, match="far more"):  # bound, far more than its own 2³ rows need
        read_cube(path)


def test_failed_write_leaves_the_existing_file_untouched(tmp_path):
    path = tmp_path / "keep.cube"
    path.write_text("original")
    with pytest.raises(ValueError):
        write_cube(path, LUT3D(identity_table(2)), title='bad "title"')
    with pytest.raises(ValueError):
        write_cube(path, LUT3D(identity_table(2), shaper="logc"), shaper_size=1)
    assert path.read_text() == "original"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.cube"]


# ---------------------------------------------------------------- the grammar other readers accept

colour = pytest.importorskip("colour")

ONE_D = "LUT_1D_SIZE 3\nLUT_1D_INPUT_RANGE -0.5 4\n0 0 0\n0.5 1.5 3\n2 2.5 5\n"
"""A 1D-only file with an input range and outputs beyond [0, 1]: nothing may be clipped."""

SPELLINGS = {
    "LF": ONE_D,
    "CRLF": ONE_D.replace("\n", "\r\n"),
    "CR": ONE_D.replace("\n", "\r"),
    "tabs": ONE_D.replace("LUT_1D_SIZE 3", "LUT_1D_SIZE\t3").replace("0.5 1.5 3", "0.5\t1.5 \t3"),
    "long title": 'TITLE "' + "t" * 5000 + '"\n' + ONE_D,
    "long comment": "#" + "c" * 5000 + "\n" + ONE_D,
    "comment among rows": ONE_D.replace("0 0 0\n", "0 0 0\n   # a note\n\n"),
    "no final line end": ONE_D[:-1],
}


@pytest.mark.parametrize("name", sorted(SPELLINGS))
def test_1d_files_in_every_spelling_apply_like_colour_science(tmp_path, name):
    path = tmp_path / "curve.cube"
    path.write_bytes(SPELLINGS[name].encode())
    rgb = np.random.default_rng(0).uniform(-0.5, 4.0, (64, 3))  # inside the input range: colour extrapolates, OCIO clamps
    expected = colour.io.read_LUT(str(path)).apply(rgb)
    image = torch.from_numpy(rgb.T.copy()).float().reshape(1, 3, 8, 8)
    for interpolation in ("tetrahedral", "trilinear"):
        ours = read_cube(path)(image, interpolation).reshape(3, -1).T.double().numpy()
        np.testing.assert_allclose(ours, expected, atol=1e-5, rtol=0)


def test_1d_file_applies_like_opencolorio(tmp_path):
    path = unique_cube(tmp_path)
    x = np.linspace(0.0, 1.0, 33)
    rows = np.stack((x**2.2, np.sqrt(x) * 3.0, 1.0 - x), axis=1)  # a gamma, an HDR lift, a decreasing curve
    with open(path, "w") as handle:
        handle.write("LUT_1D_SIZE 33\nLUT_1D_INPUT_RANGE -0.25 2\n" + "".join(f"{r:.9g} {g:.9g} {b:.9g}\n" for r, g, b in rows))
    image = torch.rand(1, 3, 32, 32) * 3.0 - 0.5
    for interpolation in ("tetrahedral", "trilinear"):
        torch.testing.assert_close(read_cube(path)(image, interpolation), ocio_apply(path, image, "trilinear"), atol=1e-4, rtol=0)


def test_opencolorio_resolve_cube_with_crlf_and_tabs_reads_like_opencolorio(tmp_path):
    path = _baked_by_opencolorio(tmp_path, "resolve_cube", True)
    text = open(path).read().replace("\n", "\r\n").replace("LUT_3D_SIZE ", "LUT_3D_SIZE\t")
    spelled = unique_cube(tmp_path)
    open(spelled, "w", newline="").write(text)
    image = torch.rand(1, 3, 16, 16) * 4.0 - 0.1
    torch.testing.assert_close(read_cube(spelled)(image), ocio_apply(spelled, image, "tetrahedral"), atol=1e-4, rtol=0)


# ---------------------------------------------------------------- errors name their line

BAD_LINES = {
    "underscore in a number": ("LUT_3D_SIZE 2\n" + _table_rows(2).replace("0.5 0.25 0.125", "1_0 0 0", 1), 2),
    "beyond float32": ("LUT_3D_SIZE 2\n# x\n" + _table_rows(2).replace("0.5 0.25 0.125\n", "1e39 0 0\n", 2), 3),
    "shaper beyond float32": ("LUT_1D_SIZE 2\nLUT_3D_SIZE 2\n0 0 0\n-1e39 1 1\n" + _table_rows(2), 4),
    "shaper nan": ("LUT_1D_SIZE 2\nLUT_3D_SIZE 2\n0 0 0\nnan 1 1\n" + _table_rows(2), 4),
    "four numbers": ("LUT_3D_SIZE 2\n\n" + _table_rows(2).replace("0.5 0.25 0.125", "0 0 0 0", 1), 3),
    "trailing comment": ("LUT_3D_SIZE 2\n" + _table_rows(2).replace("0.5 0.25 0.125", "0 0 0 # x", 1), 2),
    "one row too many": ("LUT_3D_SIZE 2\n" + _table_rows(2) + "0 0 0\n", 10),
    "unknown keyword": ("TITLE \"a\"\nLUT_3D_SIZE 2\nLUT_3D_SIZ 2\n" + _table_rows(2), 3),
    "size written 1_0": ("LUT_3D_SIZE 1_0\n" + _table_rows(2), 1),
    "crlf and a bad row": ("LUT_3D_SIZE 2\r\n" + _table_rows(2).replace("\n", "\r\n").replace("0.5 0.25 0.125", "x", 1), 2),
    "cr and a bad row": ("LUT_3D_SIZE 2\r\r" + _table_rows(2).replace("\n", "\r").replace("0.5 0.25 0.125", "x", 2), 3),
    "non-ASCII": ("LUT_3D_SIZE 2\n" + _table_rows(2).replace("0.5 0.25 0.125", "0 0 \u00e9", 3), 2),
    "control byte": ("LUT_3D_SIZE 2\n0\x1c0 0\n" + _table_rows(2), 2),
}


@pytest.mark.parametrize("name", sorted(BAD_LINES))
def test_malformed_rows_raise_value_error_naming_the_line(tmp_path, name):
    text, line = BAD_LINES[name]
    path = tmp_path / "bad.cube"
    path.write_bytes(text.encode())
    with pytest.raises(ValueError, match=f"line {line}:"):
        read_cube(path)


RANGES = {
    "1D range below float32's smallest step": "LUT_1D_SIZE 2\nLUT_1D_INPUT_RANGE 0 1e-50\nLUT_3D_SIZE 2\n0 0 0\n1 1 1\n",
    "1D range wider than float32": "LUT_1D_SIZE 2\nLUT_1D_INPUT_RANGE -3e38 3e38\nLUT_3D_SIZE 2\n0 0 0\n1 1 1\n",
    "3D domain below float32's smallest step": "DOMAIN_MIN 0 0 0\nDOMAIN_MAX 1 1e-50 1\nLUT_3D_SIZE 2\n",
    "3D range beyond float32": "LUT_3D_SIZE 2\nLUT_3D_INPUT_RANGE 0 1e39\n",
}


@pytest.mark.parametrize("name", sorted(RANGES))
def test_ranges_a_float32_lookup_cannot_divide_by_are_refused_at_read(tmp_path, name):
    path = tmp_path / "range.cube"
    path.write_text(RANGES[name] + _table_rows(2))
    with pytest.raises(ValueError, match="RANGE|domain"):
        read_cube(path)


def test_extreme_shaper_entries_give_finite_lookups_or_are_refused(tmp_path):
    """Shaper entries are lattice coordinates: one within ±1e6 (MAX_CODE) clamps to the lattice's edge, one beyond
    is refused, and entries so far apart that interpolating between them overflows float32 are refused as they
    are read."""
    path = tmp_path / "shaper.cube"
    path.write_text("LUT_1D_SIZE 3\nLUT_3D_SIZE 2\n-1e6 -1e6 -1e6\n0 0 0\n1e6 1e6 1e6\n" + _table_rows(2))
    assert torch.isfinite(read_cube(path)(torch.rand(1, 3, 4, 4) * 2 - 0.5)).all()
    path.write_text("LUT_1D_SIZE 3\nLUT_3D_SIZE 2\n-1e38 -1e38 -1e38\n0 0 0\n2e38 2e38 2e38\n" + _table_rows(2))
    with pytest.raises(ValueError, match=r"shaper curve entries must be finite and within ±1e\+06"):
        read_cube(path)
    path.write_text("LUT_1D_SIZE 3\nLUT_3D_SIZE 2\n-3e38 -3e38 -3e38\n0 0 0\n3e38 3e38 3e38\n" + _table_rows(2))
    with pytest.raises(ValueError, match="line 5: .*span"):
        read_cube(path)


# ---------------------------------------------------------------- memory and long lines


def test_reading_keeps_about_one_table_in_memory(tmp_path, monkeypatch):
    import tracemalloc

    from torchgrade.io import lines

    path = unique_cube(tmp_path)
    write_cube(path, LUT3D(torch.rand(48, 48, 48, 3)))
    monkeypatch.setattr(lines, "BLOCK_BYTES", 1 << 16)  # small blocks, so the table dominates what a read holds
    table_bytes = 48**3 * 3 * 4
    tracemalloc.start()
    try:
        lut = read_cube(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert lut.size == 48 and peak < 1.5 * table_bytes


def test_a_comment_longer_than_any_line_limit_is_skipped_and_other_long_lines_refused(tmp_path, monkeypatch):
    from torchgrade.io import lines
    from torchgrade.io.lines import MAX_LINE_BYTES

    monkeypatch.setattr(lines, "BLOCK_BYTES", 1 << 16)  # the long lines span many reads, as in a large file

    path = tmp_path / "long.cube"
    long = 3 * MAX_LINE_BYTES // 2  # within the file-size allowance of a 17³ table
    path.write_text("# " + "c" * long + "\nLUT_3D_SIZE 17\n" + _table_rows(17))
    assert read_cube(path).size == 17
    path.write_text("LUT_3D_SIZE 17\n" + " " * long + _table_rows(17))
    with pytest.raises(ValueError, match="line 2: longer than"):
        read_cube(path)


def test_1d_file_with_a_constant_channel_keeps_that_constant(tmp_path):
    path = tmp_path / "flat.cube"
    path.write_text("LUT_1D_SIZE 2\n0 65504 0.25\n1 65504 0.25\n")
    out = read_cube(path)(torch.rand(1, 3, 4, 4))
    assert torch.all(out[:, 1] == 65504.0) and torch.all(out[:, 2] == 0.25)
    path.write_text("LUT_1D_SIZE 2\n0 3e38 0.25\n1 3e38 0.25\n")
    with pytest.raises(ValueError, match=r"entries must lie in \[-65504, 65504\]"):
        read_cube(path)


def test_a_cube_with_entries_beyond_65504_is_refused_as_the_constructor_refuses_them(tmp_path):
    """±3.4e38 is finite in float32: such a file was read, and its lookups gave +Inf (tetrahedral) and NaN (trilinear)."""
    path = tmp_path / "poisoned.cube"
    rows = ["3.4e38 -3.4e38 0"] + ["0.5 0.5 0.5"] * 7
    path.write_text("LUT_3D_SIZE 2\n" + "\n".join(rows) + "\n")
    with pytest.raises(ValueError, match=r"entries must lie in \[-65504, 65504\]"):
        read_cube(path)


@pytest.mark.parametrize("title", ["Résumé, shot 12", "夜景"])
def test_a_cube_with_a_byte_order_mark_or_a_title_in_any_language_reads_back(tmp_path, title):
    path = tmp_path / "look.cube"
    write_cube(path, LUT3D(identity_table(3) ** 1.5), title=title)
    marked = tmp_path / "marked.cube"
    marked.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    for written in (path, marked):
        assert torch.equal(read_cube(written).table, read_cube(path).table)


@pytest.mark.parametrize("title", ["shot\r42", "nul\x00", "tab\tbed", 'quote"d'])
def test_a_title_a_reader_would_refuse_is_refused_when_writing(tmp_path, title):
    with pytest.raises(ValueError, match="title must be printable text"):
        write_cube(tmp_path / "look.cube", LUT3D(identity_table(2)), title=title)
    assert not list(tmp_path.iterdir())
