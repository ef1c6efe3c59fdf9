"""OpenEXR layouts beyond one RGB(A) layer: luminance/chroma, chromaticities, views, layers, parts, windows."""

import numpy as np
import OpenEXR
import pytest
import torch

import torchgrade as tg
from torchgrade.color import linear_to_srgb
from torchgrade.io.exr.yca import luminance_weights, yca_to_rgb

REC709 = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06), (0.3127, 0.3290))


def srgb_codes(image, reference):
    """Per-value absolute difference in 8-bit sRGB codes of the display-clamped RGB."""
    encode = lambda x: linear_to_srgb(x[:3].clamp(0, 1)) * 255  # noqa: E731
    return (encode(image) - encode(reference)).abs()


def raw(path, *names):
    channels = OpenEXR.File(str(path), separate_channels=True).parts[0].channels
    return torch.stack([torch.from_numpy(channels[n].pixels.astype(np.float32)) for n in names])


def window(x_min, y_min, x_max, y_max):
    return (np.array([x_min, y_min], np.int32), np.array([x_max, y_max], np.int32))


FORMATS = ["Adjuster", "Rec709", "Rec709_YC", "XYZ", "beachball_multipart.0001", "beachball_singlepart.0001",
           "displaywindow_t01", "displaywindow_t02", "displaywindow_t03", "displaywindow_t04"]


@pytest.mark.parametrize("name", FORMATS)
def test_every_format_sample_reads_its_default_rgb_in_both_windows(exr_dir, name):
    path = exr_dir / "formats" / f"{name}.exr"
    part = tg.io.exr_info(path)[0]
    for window in ("data", "display"):
        image = tg.io.read_exr(path, window=window)
        assert image.shape[0] in (3, 4) and image.shape[1:] == part.size(window) and not image.isnan().any()


@pytest.mark.parametrize("name", ["WideFloatRange", "Desk", "formats/beachball_multipart.0001", "formats/Rec709_YC"])
def test_sample_sizes_read_from_the_header_match_the_decoded_arrays(exr_dir, name):
    path = exr_dir / f"{name}.exr"
    decoded = [{n: c.pixels.dtype.itemsize for n, c in p.channels.items()} for p in OpenEXR.File(str(path), separate_channels=True).parts]
    assert [part.sample_bytes for part in tg.io.exr_info(path)] == decoded


def test_luminance_chroma_file_matches_its_rgb_twin(exr_dir):
    # The same picture stored as RGB and as Y + 2x2-subsampled RY/BY (OpenEXR's sample pair).
    error = srgb_codes(tg.io.read_exr(exr_dir / "formats" / "Rec709_YC.exr"), tg.io.read_exr(exr_dir / "formats" / "Rec709.exr"))
    assert error.mean() < 1.5 and error.flatten().quantile(0.99) < 15  # measured 1.32 and 13.3; grey would be far off


def test_constant_chroma_gives_rgb_by_the_definition_of_ry_and_by():
    weights = luminance_weights(REC709)
    y, ry, by = torch.full((6, 8), 2.0), torch.full((3, 4), 0.25), torch.full((3, 4), -0.5)
    rgb = yca_to_rgb(y, ry, by, weights).float()
    red, blue = 1.25 * 2.0, 0.5 * 2.0  # RY = (R - Y) / Y, BY = (B - Y) / Y
    green = (2.0 - weights[0] * red - weights[2] * blue) / weights[1]
    expected = torch.tensor((red, green.item(), blue)).half().float()
    torch.testing.assert_close(rgb, expected[:, None, None].expand(3, 6, 8))


def test_luminance_weights_are_the_y_row_of_rgb_to_xyz():
    import colour

    expected = colour.RGB_COLOURSPACES["ACES2065-1"].matrix_RGB_to_XYZ[1]
    aces = colour.RGB_COLOURSPACES["ACES2065-1"]
    pairs = tuple(map(tuple, aces.primaries)) + (tuple(aces.whitepoint),)
    np.testing.assert_allclose(luminance_weights(pairs).numpy(), expected / expected.sum(), atol=1e-6)


@pytest.mark.parametrize("adaptation, bound", [("auto", 1.4), ("none", 1.4), ("bradford", 60.0)])
def test_xyz_file_converts_to_its_rec709_twin_without_adaptation(exr_dir, adaptation, bound):
    # OpenEXR's README says the Chromaticities images look the same: true without adaptation
    # (1.37 codes measured), which "auto" picks for XYZ primaries; a Bradford adaptation from the
    # XYZ file's E white is 54 codes off.
    converted = tg.io.read_exr(exr_dir / "formats" / "XYZ.exr", to_rec709=True, adaptation=adaptation)
    error = srgb_codes(converted, tg.io.read_exr(exr_dir / "formats" / "Rec709.exr")).max()
    assert torch.isfinite(converted).all() and error <= bound and (adaptation != "bradford" or error > 30)


def test_ap0_file_matches_opencolorio_aces2065_1_to_linear_rec709(exr_dir):
    import PyOpenColorIO as ocio

    raw_rgb = tg.io.read_exr(exr_dir / "Carrots.exr")[:3]
    pixels = np.ascontiguousarray(raw_rgb.permute(1, 2, 0).numpy())
    config = ocio.Config.CreateFromBuiltinConfig("cg-config-latest")
    config.getProcessor("ACES2065-1", "Linear Rec.709 (sRGB)").getDefaultCPUProcessor().applyRGB(pixels)
    for adaptation in ("auto", "bradford"):  # "auto" adapts every RGB space, AP0 included (the ACES convention)
        converted = tg.io.read_exr(exr_dir / "Carrots.exr", to_rec709=True, adaptation=adaptation)[:3]
        torch.testing.assert_close(converted, torch.from_numpy(pixels).permute(2, 0, 1), atol=1e-5, rtol=1e-4)


def test_unknown_adaptation_is_a_clear_error(exr_dir):
    with pytest.raises(ValueError, match="adaptation must be one of"):
        tg.io.read_exr(exr_dir / "Carrots.exr", to_rec709=True, adaptation="cat16")


@pytest.fixture
def layered(tmp_path):
    """A two-view file: main RGB, an AOV ``mask.R``, a ``diffuse`` layer and the ``left`` view."""
    plane = lambda value: np.full((3, 5), value, np.float16)  # noqa: E731
    channels = {"R": plane(1), "G": plane(1), "B": plane(1), "mask.R": plane(5),
                "diffuse.R": plane(2), "diffuse.G": plane(2), "diffuse.B": plane(2),
                "left.R": plane(3), "left.G": plane(3), "left.B": plane(3), "left.A": plane(0.5)}
    path = tmp_path / "layered.exr"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "multiView": ["center", "left"]}
    OpenEXR.File(header, channels).write(str(path))
    return path


def test_default_read_is_the_default_views_main_layer_only(layered):
    assert tg.io.read_exr(layered).unique().tolist() == [1.0]  # not mask.R, not the left view


def test_an_aov_in_a_plain_file_does_not_replace_the_main_channel(tmp_path):
    planes = {"R": np.ones((2, 3), np.float32), "G": np.ones((2, 3), np.float32), "B": np.ones((2, 3), np.float32),
              "mask.R": np.zeros((2, 3), np.float32)}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, planes).write(str(tmp_path / "aov.exr"))
    assert tg.io.read_exr(tmp_path / "aov.exr").eq(1).all()
    assert tg.io.read_exr(tmp_path / "aov.exr", layer="mask").tolist() == [[[0.0] * 3] * 2, [[0.0] * 3] * 2, [[0.0] * 3] * 2]


@pytest.mark.parametrize("options, expected", [({"layer": "diffuse"}, [2.0] * 3), ({"view": "left"}, [3.0, 3.0, 3.0, 0.5]),
                                               ({"layer": "mask"}, [5.0, 0.0, 0.0])])  # as OpenEXR: missing G, B are 0
def test_any_layer_or_view_reads_on_request(layered, options, expected):
    image = tg.io.read_exr(layered, **options)
    assert image.shape[1:] == (3, 5) and image[:, 0, 0].tolist() == expected


def test_exr_info_lists_views_layers_and_windows(layered):
    part, = tg.io.exr_info(layered)
    assert part.views == ("center", "left") and part.data_window == (0, 0, 4, 2)
    assert part.layers == {("center", ""): ["B", "G", "R"], (None, "mask"): ["R"], (None, "diffuse"): ["B", "G", "R"],
                           ("left", ""): ["A", "B", "G", "R"]}


def test_missing_layer_or_view_names_what_the_file_holds(layered):
    with pytest.raises(ValueError, match="layer 'specular'.*diffuse"):
        tg.io.read_exr(layered, layer="specular")
    with pytest.raises(ValueError, match="view 'right'"):
        tg.io.read_exr(layered, view="right")


@pytest.fixture
def multipart(tmp_path):
    left = OpenEXR.Part({"name": "beauty", "view": "left", "dataWindow": window(2, 1, 7, 4), "displayWindow": window(0, 0, 9, 9)},
                        {"R": np.ones((4, 6), np.float32), "G": np.ones((4, 6), np.float32), "B": np.ones((4, 6), np.float32)})
    depth = OpenEXR.Part({"name": "depth", "dataWindow": window(0, 0, 2, 1), "displayWindow": window(0, 0, 9, 9)},
                         {"Z": np.full((2, 3), 7, np.float32)})
    path = tmp_path / "parts.exr"
    OpenEXR.File([left, depth]).write(str(path))
    return path


def test_parts_are_chosen_by_index_name_or_view_and_placed_in_the_display_window(multipart):
    assert tg.io.read_exr(multipart).shape == (3, 4, 6)
    assert tg.io.read_exr(multipart, view="left").shape == (3, 4, 6)
    depth = tg.io.read_exr(multipart, part="depth", window="display", layer="")  # the main layer holds only Z
    assert depth.shape == (1, 10, 10) and depth[0, :2, :3].eq(7).all() and depth.sum() == 7 * 6
    framed = tg.io.read_exr(multipart, part="beauty", window="display")
    assert framed.shape == (3, 10, 10) and framed[:, 1:5, 2:8].eq(1).all() and framed.sum() == 3 * 24


def test_adjuster_views_match_their_raw_channels(exr_dir):
    path = exr_dir / "formats" / "Adjuster.exr"
    torch.testing.assert_close(tg.io.read_exr(path), raw(path, "R", "G", "B"), atol=0, rtol=0)
    torch.testing.assert_close(tg.io.read_exr(path, view="right"), raw(path, "right.R", "right.G", "right.B"), atol=0, rtol=0)


def test_stereo_frame_reads_the_same_from_one_part_or_many(exr_dir):
    single, multi = exr_dir / "formats" / "beachball_singlepart.0001.exr", exr_dir / "formats" / "beachball_multipart.0001.exr"
    torch.testing.assert_close(tg.io.read_exr(single), raw(single, "R", "G", "B", "A"), atol=0, rtol=0)
    for view in ("right", "left"):
        one = tg.io.read_exr(single, view=view, window="display")
        many = tg.io.read_exr(multi, view=view, window="display")
        assert one.shape == many.shape == (4, 1556, 2048)
        torch.testing.assert_close(one, many, atol=0, rtol=0)


def test_a_layer_of_a_view_reads_the_same_from_one_part_or_many(exr_dir):
    single, multi = exr_dir / "formats" / "beachball_singlepart.0001.exr", exr_dir / "formats" / "beachball_multipart.0001.exr"
    one = tg.io.read_exr(single, layer="forward", view="left", window="display")
    many = tg.io.read_exr(multi, layer="forward", view="left", window="display")
    assert one.shape == (2, 1556, 2048)  # u, v
    torch.testing.assert_close(one, many, atol=0, rtol=0)


@pytest.mark.parametrize("name", ["displaywindow_t01", "displaywindow_t02", "displaywindow_t03", "displaywindow_t04"])
def test_display_window_places_the_data_window(exr_dir, name):
    path = exr_dir / "formats" / f"{name}.exr"
    part, = tg.io.exr_info(path)
    x0, y0, x1, y1 = part.display_window
    framed = tg.io.read_exr(path, window="display")
    data = tg.io.read_exr(path)
    assert framed.shape[1:] == (y1 - y0 + 1, x1 - x0 + 1) and data.shape[1:] == (300, 400)
    # the data window is (0, 0)-(399, 299) in all four, so display pixel (x, y) is data pixel (x, y)
    expected = torch.zeros_like(framed)
    inside = data[:, y0:min(y1, 299) + 1, x0:min(x1, 399) + 1]
    expected[:, :inside.shape[1], :inside.shape[2]] = inside
    torch.testing.assert_close(framed, expected, atol=0, rtol=0)


@pytest.mark.parametrize("display", [(-3, -2, 20, 14), (2, 3, 9, 6)])
def test_luminance_chroma_in_a_display_window_is_the_data_window_placed(tmp_path, display):
    # around the data window (the result written in place) and inside it (reconstructed, then cropped)
    rng = np.random.default_rng(1)
    y, chroma = rng.random((12, 16)) * 4 + 0.01, rng.random((2, 12, 16)) - 0.5
    channels = {"Y": y.astype(np.float16), **{n: OpenEXR.Channel(c.astype(np.float16), 2, 2) for n, c in zip(("RY", "BY"), chroma)}}
    header = {"type": OpenEXR.scanlineimage, "dataWindow": window(0, 0, 15, 11), "displayWindow": window(*display)}
    path = tmp_path / "yc.exr"
    OpenEXR.File(header, channels).write(str(path))
    data, framed = tg.io.read_exr(path), tg.io.read_exr(path, window="display")
    x0, y0, x1, y1 = display
    expected = torch.zeros(3, y1 - y0 + 1, x1 - x0 + 1)
    inside = data[:, max(y0, 0):min(y1, 11) + 1, max(x0, 0):min(x1, 15) + 1]
    expected[:, max(-y0, 0):max(-y0, 0) + inside.shape[1], max(-x0, 0):max(-x0, 0) + inside.shape[2]] = inside
    assert data.shape == (3, 12, 16) and (data[0] - data[2]).abs().max() > 0.1  # in colour
    torch.testing.assert_close(framed, expected, atol=0, rtol=0)


def write_tiled_layers(path):
    """Tiled 16×16, data window offset and inside a larger display window: half RGB, float Z, a
    ``diffuse`` layer, and an ``obj`` layer mixing uint and half samples."""
    rng = np.random.default_rng(3)
    half = lambda: (rng.standard_normal((37, 29)) * 100).astype(np.float16)  # noqa: E731
    channels = {"R": half(), "G": half(), "B": half(), "Z": rng.random((37, 29), np.float32),
                "diffuse.R": half(), "diffuse.G": half(), "diffuse.B": half(),
                "obj.id": rng.integers(0, 2**32, (37, 29), dtype=np.uint32), "obj.w": half()}
    tiles = OpenEXR.TileDescription()
    tiles.xSize = tiles.ySize = 16
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.tiledimage, "tiles": tiles,
              "dataWindow": window(-3, 5, 25, 41), "displayWindow": window(0, 0, 30, 50)}
    OpenEXR.File(header, channels).write(str(path))


def test_reads_in_strips_equal_whole_reads_bit_for_bit(exr_dir, tmp_path, monkeypatch):
    from torchgrade.io.exr import decode, read

    write_tiled_layers(tmp_path / "tiled.exr")
    paths = sorted(exr_dir.glob("*.exr")) + sorted((exr_dir / "formats").glob("*.exr")) + [tmp_path / "tiled.exr"]
    strips = []
    monkeypatch.setattr(read, "decode_strips", lambda *args: strips.append(args[0]) or decode.decode_strips(*args))
    monkeypatch.setattr(decode, "STRIP_BYTES", 1)  # one row per strip
    for path in paths:
        parts = tg.io.exr_info(path)
        if parts[0].deep:
            continue
        for view, layer in sorted(parts[0].layers, key=str):
            for window in ("data", "display"):
                before = len(strips)
                striped = tg.io.read_exr(path, layer=layer, view=view, part=0, window=window)
                if len(strips) == before:
                    continue
                with monkeypatch.context() as whole:
                    whole.setattr(read, "selective", lambda *args: False)
                    expected = tg.io.read_exr(path, layer=layer, view=view, part=0, window=window)
                assert torch.equal(striped.view(torch.int32), expected.view(torch.int32)), (path.name, view, layer, window)
    assert {path.name for path in strips} >= {"Adjuster.exr", "beachball_multipart.0001.exr", "beachball_singlepart.0001.exr",
                                              "tiled.exr"}
    assert len(strips) >= 20


COMPRESSIONS = sorted(name for name in dir(OpenEXR) if name.endswith("_COMPRESSION"))
"""Every compression the installed OpenEXR names (3.5.3: NO to DWAB, HTJ2K256, HTJ2K32, LJ2K, ZSTD)."""
LOSSY = {"B44_COMPRESSION", "B44A_COMPRESSION", "DWAA_COMPRESSION", "DWAB_COMPRESSION", "LJ2K_COMPRESSION"}
"""Compressions that may change half samples (PXR24 keeps halves exactly: it rounds 32-bit floats only)."""


def write_compressed(path, compression: str, kind: str, rgb: np.ndarray) -> None:
    """``rgb`` written with ``compression`` as a scanline or tiled file, or as the second part of a two-part file."""
    header = {"compression": getattr(OpenEXR, compression), "type": OpenEXR.tiledimage if kind == "tiled" else OpenEXR.scanlineimage}
    if kind == "tiled":
        tiles = OpenEXR.TileDescription()
        tiles.xSize = tiles.ySize = 16
        header["tiles"] = tiles
    if kind == "multi-part":
        parts = [OpenEXR.Part(dict(header), {"RGB": rgb[::-1].copy()}, name="first"), OpenEXR.Part(dict(header), {"RGB": rgb}, name="second")]
        OpenEXR.File(parts).write(str(path))
    else:
        OpenEXR.File(header, {"RGB": rgb}).write(str(path))


@pytest.mark.parametrize("kind", ["scanline", "tiled", "multi-part"])
@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_every_compression_the_library_writes_reads_back(tmp_path, compression, kind):
    rgb = (np.random.default_rng(5).random((300, 24, 3)) * 8).astype(np.float16)  # 300 lines: two blocks of 256
    path = tmp_path / f"{compression}.exr"
    write_compressed(path, compression, kind, rgb)
    part = 1 if kind == "multi-part" else 0
    expected = OpenEXR.File(str(path)).parts[part].channels["RGB"].pixels if compression in LOSSY else rgb
    image = tg.io.read_exr(path, part=part)
    assert torch.equal(image, torch.from_numpy(expected.astype(np.float32)).permute(2, 0, 1))


def test_a_compression_the_chunk_checks_do_not_know_is_left_to_the_library(tmp_path, monkeypatch):
    from torchgrade.io.exr import chunks

    rgb = (np.random.default_rng(6).random((40, 8, 3)) * 8).astype(np.float16)
    write_compressed(tmp_path / "alone.exr", "ZSTD_COMPRESSION", "scanline", rgb)
    write_compressed(tmp_path / "parts.exr", "ZSTD_COMPRESSION", "multi-part", rgb)
    monkeypatch.setattr(chunks, "_LINES_PER_CHUNK", {code: lines for code, lines in chunks._LINES_PER_CHUNK.items()
                                                     if code != int(OpenEXR.ZSTD_COMPRESSION)})  # as a newer code would be
    assert torch.equal(tg.io.read_exr(tmp_path / "alone.exr"), torch.from_numpy(rgb.astype(np.float32)).permute(2, 0, 1))
    with pytest.raises(ValueError, match="cannot be copied out of its multi-part file"):
        tg.io.read_exr(tmp_path / "parts.exr", part=1)


def test_a_compression_the_library_does_not_know_either_is_refused_before_decoding(tmp_path):
    """OpenEXR 3.5.3 reads an unknown compression code as ZIP, without a word: such a file is refused here."""
    path = tmp_path / "unknown.exr"
    write_compressed(path, "NO_COMPRESSION", "scanline", np.ones((4, 4, 3), np.float16))
    data = bytearray(path.read_bytes())
    data[data.index(b"compression\0compression\0") + 28] = 200  # after the names and the 4-byte size
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="its compression 200 is none the installed OpenEXR knows"):
        tg.io.read_exr(path)
