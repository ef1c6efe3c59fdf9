"""Small OpenEXR files whose headers ask for huge allocations: refused from the headers, before the
bindings allocate anything, with a ValueError naming the field and the size."""

import json
import os
import re
import struct
import subprocess
import sys

import numpy as np
import OpenEXR
import pytest
import torch

import torchgrade as tg

BOMB = """
import json, resource, sys, time, torchgrade as tg
def status(key):
    return int(next(line for line in open("/proc/self/status") if line.startswith(key)).split()[1]) * 1024
size = status("VmSize")
resource.setrlimit(resource.RLIMIT_AS, (size + (1 << 30), resource.RLIM_INFINITY))  # a bomb fails fast, not the machine
for path, options in json.loads(sys.argv[1]):
    with open("/proc/self/clear_refs", "w") as clear:
        clear.write("5")  # resets the peak (VmHWM) to the resident size now
    before, start = status("VmRSS"), time.process_time()
    try:
        tg.io.read_exr(path, **options)
        outcome = "read"
    except Exception as error:
        outcome = f"{type(error).__name__}: {error}"
    print(json.dumps([time.process_time() - start, status("VmHWM") - before, outcome]))
"""


def read_bombs(reads):
    """``(CPU seconds, peak bytes above the resident size before, outcome)`` of each ``(path, options)`` read in
    a child process whose address space may grow by 1 GiB at most."""
    result = subprocess.run([sys.executable, "-c", BOMB, json.dumps([(str(path), options) for path, options in reads])],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    return [json.loads(line) for line in result.stdout.splitlines()]


def tall_tiles(path, tile_height):
    """A 56x40 RGB float file, uncompressed (27 KB), in one row of 16x40 tiles, whose ``tiles``
    attribute then says the tiles are ``tile_height`` rows tall: the chunk count and offset table stay
    those of a valid file (one row of four tiles)."""
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize = 16, 40
    rng = np.random.default_rng(0)
    header = {"type": OpenEXR.tiledimage, "tiles": tiles, "compression": OpenEXR.NO_COMPRESSION}
    OpenEXR.File(header, {c: rng.random((40, 56), np.float32) for c in "RGB"}).write(str(path))
    data = bytearray(path.read_bytes())
    at = data.index(b"tiles\0tiledesc\0") + len(b"tiles\0tiledesc\0") + 4
    struct.pack_into("<I", data, at + 4, tile_height)
    path.write_bytes(bytes(data))
    return path


def framed_pixel(path, side):
    """A 1x1 RGB half data window in a ``side``² display window (364 bytes)."""
    window = lambda x0, y0, x1, y1: (np.array([x0, y0], np.int32), np.array([x1, y1], np.int32))  # noqa: E731
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "dataWindow": window(0, 0, 0, 0),
              "displayWindow": window(0, 0, side - 1, side - 1)}
    OpenEXR.File(header, {c: np.ones((1, 1), np.float16) for c in "RGB"}).write(str(path))
    return path


@pytest.mark.skipif(not os.path.exists("/proc/self/clear_refs"), reason="needs Linux's peak-memory reset")
def test_bombs_are_refused_from_the_header_without_allocating(tmp_path):
    # before: 16 s and a 6.9 GB peak for the 10-million-row tiles (the bindings buffer a row of tiles,
    # tile height x data-window width, per channel: 56 x 1e7 x 4 bytes x 3), std::bad_alloc at 2e7;
    # and the 12000² canvas of a 364-byte file was allocated (1.73 GB)
    tall, taller = tall_tiles(tmp_path / "tall.exr", 10_000_000), tall_tiles(tmp_path / "taller.exr", 20_000_000)
    framed, wider = framed_pixel(tmp_path / "framed.exr", 12000), framed_pixel(tmp_path / "wider.exr", 16000)
    assert tall.stat().st_size < 28_000 and framed.stat().st_size < 400
    above_bytes, above_pixels = ".*max_bytes", r"is empty or above the budget of 67108864 pixels \(max_pixels\)"
    cases = [(tall, {}, r"part 0 tiles \(tileDesc\) 16x10000000 makes reading need about 6720053760 bytes" + above_bytes),
             (taller, {}, r"part 0 tiles \(tileDesc\) 16x20000000 makes reading need about 13440053760 bytes" + above_bytes),
             (framed, {"window": "display", "max_bytes": 1 << 30, "max_pixels": 1 << 28},
              r"part 0 displayWindow 12000x12000 makes reading need about 1728000006" + above_bytes),
             (wider, {"window": "display"}, "displayWindow 16000x16000 " + above_pixels)]
    for (path, _, message), (seconds, peak, outcome) in zip(cases, read_bombs([(path, options) for path, options, _ in cases])):
        assert re.match(rf"ValueError: {re.escape(str(path))}: {message}", outcome), outcome
        assert peak < 32 << 20, (path.name, seconds, peak)  # refused from the header: no buffer the size of the canvas


def test_a_tile_taller_than_the_data_window_reads_when_its_row_of_tiles_fits_the_budget(tmp_path):
    # a tile may pass the data window (writers keep 64x64 tiles for smaller images): what counts is the
    # row of tiles the library buffers, 1000 x 56 pixels x 12 bytes here
    path, plain = tall_tiles(tmp_path / "tall.exr", 1000), tall_tiles(tmp_path / "plain.exr", 40)
    channels = OpenEXR.File(str(plain), separate_channels=True).parts[0].channels
    expected = torch.from_numpy(np.stack([channels[c].pixels for c in "RGB"]))
    decoded, returned, rows = 56 * 40 * 12, 3 * 56 * 40 * 4, 1000 * 56 * 12
    assert torch.equal(tg.io.read_exr(path, max_bytes=decoded + returned + rows), expected)
    with pytest.raises(ValueError, match=rf"tall\.exr: part 0 tiles \(tileDesc\) 16x1000 .*\({decoded} decoded \+ {returned} "
                                         rf"returned \+ {rows} in the library's row of tiles\)"):
        tg.io.read_exr(path, max_bytes=decoded + returned + rows - 1)


def test_a_display_window_read_counts_the_canvas_and_a_data_window_read_does_not(tmp_path):
    path = framed_pixel(tmp_path / "framed.exr", 12000)
    assert tg.io.read_exr(path, max_bytes=1 << 30).tolist() == [[[1.0]], [[1.0]], [[1.0]]]
    with pytest.raises(ValueError, match=r"framed\.exr: part 0 displayWindow 12000x12000 .*\(6 decoded \+ 1728000000 returned\)"):
        tg.io.read_exr(path, window="display", max_bytes=1 << 30, max_pixels=1 << 28)
    with pytest.raises(ValueError, match=r"framed\.exr: displayWindow 12000x12000 is empty or above the budget of 67108864 pixels"):
        tg.io.read_exr(path, window="display")  # the default pixel budget refuses the canvas first
