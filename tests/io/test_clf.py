"""CLF (Academy/ASC Common LUT Format) files, applied by OpenColorIO, and 3D-only .cube files for 3D-only readers:
colour-science, OpenColorIO and ffmpeg's ``lut3d`` filter (the binary of the ``imageio-ffmpeg`` wheel, or one on PATH)."""

import itertools
import shutil
import subprocess
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import torch

OCIO = pytest.importorskip("PyOpenColorIO")
colour = pytest.importorskip("colour")

import torchgrade as tg  # noqa: E402
from torchgrade.color.transfer import LOGC_A, LOGC_B, LOGC_C, LOGC_D  # noqa: E402
from torchgrade.io import write_clf, write_cube  # noqa: E402
from torchgrade.lut import LUT3D, LUTAccuracyWarning, code_errors, identity_table, validation_colours  # noqa: E402

_names = itertools.count()
OCIO_INTERPOLATION = {"tetrahedral": OCIO.INTERP_TETRAHEDRAL, "trilinear": OCIO.INTERP_LINEAR}


@pytest.fixture(scope="module")
def looks():
    look = torch.nn.Sequential(tg.ColorGrade(contrast=20.0, saturation=10.0, temperature=10.0), tg.ToneMap("aces"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        luts = {shaper: tg.bake_lut(look, size=9, shaper=shaper) for shaper in ("linear", "logc", "logc_hdr", "logc_extended", "fitted")}
        luts["fitted to a scene"] = tg.bake_lut(look, size=9, shaper="fitted", scene=hdr_image(), entries="fitted")
        return luts


def ocio_apply(path, image: torch.Tensor, interpolation: str) -> torch.Tensor:
    transform = OCIO.FileTransform(src=str(path), interpolation=OCIO_INTERPOLATION[interpolation])
    processor = OCIO.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor()
    pixels = np.ascontiguousarray(image[0].permute(1, 2, 0).numpy().astype(np.float32))
    processor.applyRGB(pixels)
    return torch.from_numpy(pixels).permute(2, 0, 1).unsqueeze(0)


def hdr_image() -> torch.Tensor:
    image = torch.exp(torch.randn(1, 3, 24, 24) * 3.0 - 1.0)
    image[0, :, 0, :5] = torch.tensor([0.0, 1e-4, 58.86, 1000.0, 65504.0])
    return image


@pytest.mark.parametrize("shaper", ["linear", "logc", "logc_hdr", "logc_extended", "fitted", "fitted to a scene"])
@pytest.mark.parametrize("interpolation", ["tetrahedral", "trilinear"])
def test_opencolorio_applies_the_clf_as_the_lut_does(tmp_path, looks, shaper, interpolation):
    lut = looks[shaper]
    path = tmp_path / f"look{next(_names)}.clf"
    write_clf(path, lut, interpolation=interpolation)
    image = hdr_image()
    with torch.no_grad():
        torch.testing.assert_close(ocio_apply(path, image, interpolation), lut(image, interpolation), atol=1e-4, rtol=0)


def test_the_logc_shaper_is_an_exact_log_node_and_the_lattice_a_range(tmp_path, looks):
    path = tmp_path / "logc.clf"
    write_clf(path, looks["logc"])
    root = ET.parse(path).getroot()
    assert [node.tag for node in root if node.tag != "Description"] == ["Log", "Range", "LUT3D", "Range"]
    params = root.find("Log/LogParams").attrib
    assert root.find("Log").get("style") == "linToLog" and params["base"] == "10"
    assert [float(params[k]) for k in ("linSideSlope", "linSideOffset", "logSideSlope", "logSideOffset")] == [LOGC_A, LOGC_B, LOGC_C, LOGC_D]
    assert float(root.find("Range/maxInValue").text) == pytest.approx(1.0)


@pytest.mark.parametrize("shaper", ["logc_hdr", "logc_extended"])
def test_the_tail_is_an_exact_piecewise_linear_lut1d_after_the_log_node(tmp_path, looks, shaper):
    """Log (LogC), then a Range and a LUT1D whose points include the knots (LogC codes 1 and 1.3), so its linear
    interpolation is the shaper itself: OpenColorIO gives the shaper's code values, 65504 included."""
    lut = looks[shaper]
    path = tmp_path / "hdr.clf"
    write_clf(path, lut)
    root = ET.parse(path).getroot()
    assert [node.tag for node in root if node.tag != "Description"] == ["Log", "Range", "LUT1D", "Range", "LUT3D", "Range"]
    shaper_only = tmp_path / "shaper.clf"
    nodes = "".join(ET.tostring(node, encoding="unicode") for node in list(root)[1:4])
    shaper_only.write_text(f'<?xml version="1.0" encoding="UTF-8"?>\n<ProcessList compCLFversion="3" id="s">{nodes}</ProcessList>\n')
    linear = torch.tensor([0.0, 1e-4, 0.18, 58.0, 58.8566, 60.0, 500.0, 997.0, 1000.0, 20000.0, 65504.0])
    image = linear.repeat(3, 1).reshape(1, 3, 1, -1)
    expected = tg.lut.SHAPERS[shaper].encode(linear.double())
    torch.testing.assert_close(ocio_apply(shaper_only, image, "trilinear")[0, 0, 0].double(), expected, atol=2e-6, rtol=0)


def test_a_failed_clf_write_leaves_nothing(tmp_path, looks):
    path = tmp_path / "bad.clf"
    with pytest.raises(ValueError, match="interpolation"):
        write_clf(path, looks["logc"], interpolation="cubic")
    assert list(tmp_path.iterdir()) == []


def test_3d_only_cube_is_read_by_colour_and_opencolorio_and_reports_its_cost(tmp_path, looks):
    lut = looks["logc"]
    path = tmp_path / "flat.cube"
    cost = write_cube(path, lut, shaper_section=False)
    text = path.read_text()
    assert "LUT_1D_SIZE" not in text and "LUT_3D_SIZE 9" in text
    read = colour.io.read_LUT_IridasCube(str(path))
    assert isinstance(read, colour.LUT3D) and read.table.shape == (9, 9, 9, 3)
    image = torch.rand(1, 3, 16, 16)
    ours = torch.from_numpy(read.apply(image[0].permute(1, 2, 0).double().numpy())).permute(2, 0, 1).unsqueeze(0)
    torch.testing.assert_close(ocio_apply(path, image, "trilinear").double(), ours, atol=1e-5, rtol=0)
    colours = validation_colours(hdr=False).reshape(1, 3, 1, -1)
    flat = ocio_apply(path, colours.float(), "tetrahedral")
    with torch.no_grad():
        errors = code_errors(lut(colours.float()), flat).flatten()
    assert cost.max == pytest.approx(float(errors.max()), abs=0.05)  # what the resampling costs, as a reader applies it
    assert write_cube(tmp_path / "lin.cube", looks["linear"], shaper_section=False) is None  # nothing to resample


def ffmpeg_binary():
    """ffmpeg from the ``imageio-ffmpeg`` wheel (the test extra), else from PATH, else None."""
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        return shutil.which("ffmpeg")


@pytest.mark.parametrize("interpolation", ["trilinear", "tetrahedral"])
def test_3d_only_cube_applied_by_ffmpeg_lut3d_matches_the_lookup(tmp_path, interpolation):
    """A float image through ``ffmpeg -vf lut3d`` (planar float32, ``gbrpf32le``: planes G, B, R) equals LUT3D's lookup."""
    binary = ffmpeg_binary()
    if binary is None:
        pytest.skip("no ffmpeg binary: install the test extra (imageio-ffmpeg)")
    generator = torch.Generator().manual_seed(3)
    size, height, width = 9, 8, 16
    table = identity_table(size, torch.float64) ** 1.5 * 0.8 + 0.1 * torch.rand(size, size, size, 3, generator=generator, dtype=torch.float64)
    lut = LUT3D(table)
    cube = tmp_path / "flat.cube"
    assert write_cube(cube, lut, shaper_section=False) is None
    image = torch.rand(1, 3, height, width, generator=generator, dtype=torch.float64)
    image[0, :, 0, :3] = torch.tensor([[0.0, 1.0, 0.5]] * 3)  # lattice corners and a lattice plane
    source, result = tmp_path / "in.raw", tmp_path / "out.raw"
    image[0][[1, 2, 0]].float().numpy().tofile(source)
    raw = ["-f", "rawvideo", "-pix_fmt", "gbrpf32le"]
    subprocess.run([binary, "-v", "error", "-y", *raw, "-s", f"{width}x{height}", "-i", str(source),
                    "-vf", f"lut3d=file={cube}:interp={interpolation}", *raw, str(result)], check=True, capture_output=True)
    applied = torch.from_numpy(np.fromfile(result, dtype=np.float32).reshape(3, height, width)[[2, 0, 1]].copy())
    with torch.no_grad():
        torch.testing.assert_close(applied.double(), lut(image, interpolation)[0], atol=1e-6, rtol=0)
