"""Every door bounded: each reader checks what a file costs before paying it. Each case runs in a child process capped
at 1 GiB more than it holds after ``import torchgrade`` (:func:`bounded.run_bounded`), and must end with a clear error
(or the right result) within 1 GiB and :data:`CPU_SECONDS` of work: far above what a refusal costs (0.7 s at most,
imports included, on a busy 2-core machine), far below what the attacks cost before (16 s to more than 600 s)."""

import json
import os
import threading

import pytest

from bounded import run_bounded

CPU_SECONDS, BYTES = 10.0, 1 << 30


def assert_refused(code: str, message: str) -> None:
    seconds, peak, outcome = run_bounded(code)
    assert outcome.startswith("ValueError") and message in outcome, outcome
    assert seconds <= CPU_SECONDS and peak <= BYTES, (seconds, peak)


def clf(body: str, declaration: str = "") -> str:
    return (f'<?xml version="1.0" encoding="UTF-8"?>{declaration}\n<ProcessList id="x" compCLFversion="3">\n{body}\n'
            "</ProcessList>\n")


def lut3d(array: str, dim: str = "2 2 2 3", attributes: str = 'inBitDepth="32f" outBitDepth="32f"') -> str:
    return f'<LUT3D {attributes}><Array dim="{dim}">{array}</Array></LUT3D>'


IDENTITY = " ".join(f"{r} {g} {b}" for r in (0, 1) for g in (0, 1) for b in (0, 1))


# ---------------------------------------------------------------- CLF


def test_a_clf_table_far_longer_than_its_dim_is_refused_as_it_streams_in(tmp_path):
    """A 2x2x2 table followed by 40 MB of numbers (under the 256 MiB file cap): refused a kilobyte into the Array,
    where it took 7.2 GB and 49 s before (the whole file parsed, then counted)."""
    path = tmp_path / "long.clf"
    with open(path, "w") as handle:
        handle.write(clf(lut3d(IDENTITY + " 0.5" * (20 << 20))))
    assert_refused(f"tg.io.read_clf({str(path)!r})", "far more text than its dim declares")


def test_a_clf_with_an_internal_entity_is_refused_unread(tmp_path):
    """An entity grown below expat's amplification guard (a 1.3 MB file that expanded to 3.0 GB before): no DOCTYPE."""
    path = tmp_path / "entity.clf"
    declaration = '<!DOCTYPE ProcessList [<!ENTITY n "' + "1 " * 650_000 + '">]>'
    path.write_text(clf(lut3d("&n;" * 2000), declaration))
    assert_refused(f"tg.io.read_clf({str(path)!r})", "no DOCTYPE")


def test_too_many_clf_elements_are_refused_and_the_error_stays_short(tmp_path):
    """A 30 MB file of nodes: refused at the 4,097th element with a short message (39 MB of stderr before)."""
    path = tmp_path / "nodes.clf"
    path.write_text(clf('<Matrix inBitDepth="32f" outBitDepth="32f"/>' * 1_000_000))
    seconds, peak, outcome = run_bounded(f"tg.io.read_clf({str(path)!r})")
    assert outcome.startswith("ValueError") and "XML elements" in outcome and len(outcome) < 400, outcome[:500]
    assert seconds <= CPU_SECONDS and peak <= BYTES
    path.write_text(clf('<Matrix inBitDepth="32f" outBitDepth="32f"/>' * 3000 + lut3d(IDENTITY)))
    seconds, peak, outcome = run_bounded(f"tg.io.read_clf({str(path)!r})")
    assert "2993 more]" in outcome and len(outcome) < 600, outcome[:700]


def test_a_no_clamp_range_after_the_table_does_not_clamp(tmp_path):
    """``style="noClamp"`` scales without clamping (SMPTE ST 2136-1): a table entry of 2.5 comes out 2.5 (1.0 before)."""
    import torch

    import torchgrade as tg

    bounds = "<minInValue>0</minInValue><maxInValue>1</maxInValue><minOutValue>0</minOutValue><maxOutValue>1</maxOutValue>"
    bright = " ".join(["2.5 2.5 2.5"] * 8)
    for style, expected in (('style="noClamp"', 2.5), ("", 1.0), ('style="Clamp"', 1.0)):
        path = tmp_path / "range.clf"
        path.write_text(clf(lut3d(bright) + f'<Range inBitDepth="32f" outBitDepth="32f" {style}>{bounds}</Range>'))
        out = tg.io.read_clf(path)(torch.full((1, 3, 1, 1), 0.5))
        assert out.flatten().tolist() == [expected] * 3, style
    path.write_text(clf(lut3d(bright) + f'<Range style="clip">{bounds}</Range>'))
    with pytest.raises(ValueError, match="Clamp or noClamp"):
        tg.io.read_clf(path)


# ---------------------------------------------------------------- pipes and devices


def _fifo(tmp_path, name):
    path = tmp_path / name
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("reader, name", [
    ("tg.io.read_cube", "look.cube"),
    ("tg.io.read_clf", "look.clf"),
    ("tg.io.read_exr", "frame.exr"),
    ("tg.base.config.load_config", "look.json"),
    ("tg.LookLUT", "look.cube"),
])
def test_a_pipe_is_refused_without_waiting_for_a_writer(tmp_path, reader, name):
    """A FIFO named as a LUT, a frame or a config: refused at once (it hung for ever before)."""
    path = _fifo(tmp_path, name)
    assert_refused(f"{reader}({str(path)!r})", "not a regular file")


def test_a_config_naming_a_pipe_as_its_look_lut_is_refused(tmp_path):
    path = _fifo(tmp_path, "look.cube")
    config = tmp_path / "look.json"
    config.write_text(json.dumps({"tonemap": "aces", "look_lut": str(path)}))
    assert_refused(f"tg.PostFX.from_config({str(config)!r})", "not a regular file")


def test_a_pipe_with_a_writer_cannot_pass_the_clf_size_cap(tmp_path):
    """A pipe fed 400 MiB by a writer: refused as a pipe, nothing read (400 MiB were parsed before)."""
    path = _fifo(tmp_path, "fed.clf")

    def feed():
        try:
            with open(path, "wb") as pipe:
                for _ in range(400):
                    pipe.write(b"0 " * (1 << 19))
        except (BrokenPipeError, OSError):
            pass

    writer = threading.Thread(target=feed, daemon=True)
    writer.start()
    assert_refused(f"tg.io.read_clf({str(path)!r})", "not a regular file")
    with open(path, "rb"):  # let the writer finish: it opened the pipe and waits for a reader
        pass
    writer.join(timeout=10)


@pytest.mark.parametrize("reader, what", [
    ("tg.io.read_cube", ".cube file"),
    ("tg.io.read_clf", "CLF file"),
    ("tg.base.config.load_config", "config"),
    ("tg.io.load_compile_cache", "compile cache"),
])
@pytest.mark.parametrize("kernel_file", ["/proc/self/mem", "/proc/self/status"])
def test_a_kernel_file_is_refused_before_it_is_read(reader, what, kernel_file):
    """``/proc/self/mem`` as a ``.cube`` raised a bare OSError (EIO) from its first read: a kernel file is a regular
    file of size 0 whatever it holds, refused as empty before a byte is read."""
    if not os.path.exists(kernel_file):
        pytest.skip("platform-conditional: needs Linux's /proc")
    assert_refused(f"{reader}({kernel_file!r})", f"{what} {kernel_file} is empty (0 bytes")


def test_a_file_that_grows_while_it_is_read_is_read_no_further_than_its_budget(tmp_path):
    """The size is checked on the open file, then the handle itself stops at the budget: bytes appended after the
    check are refused when the read reaches them (a byte past the budget), not read on."""
    from torchgrade.base.files import open_regular

    path = tmp_path / "growing.cube"
    path.write_bytes(b"LUT_3D_SIZE 2\n")
    with open_regular(path, 64, ".cube file") as handle:
        with open(path, "ab") as writer:
            writer.write(b"0 0 0\n" * 1000)
        with pytest.raises(ValueError, match=r"larger than 64 bytes \(it grew as it was read\)"):
            handle.read()
        assert handle.raw.tell() == 65  # the budget and the one byte that told
    with open_regular(path, 8000, ".cube file") as handle:  # within its budget: read whole
        assert len(handle.read()) == 6014


# ---------------------------------------------------------------- EXR headers


def test_an_exr_header_of_many_empty_attributes_is_refused_before_openexr_parses_it(tmp_path):
    """200,000 empty attributes (3 MB) in a valid file's header: refused by the attribute budget in milliseconds
    (OpenEXR's own parser took 198 s, 1M of them more than 600 s), by read_exr and exr_info alike."""
    import struct

    import torch

    import torchgrade as tg
    from torchgrade.io.exr.header_bytes import MAX_ATTRIBUTES, read_headers

    path = tmp_path / "attributes.exr"
    tg.io.write_exr(path, torch.zeros(3, 4, 4))
    data = path.read_bytes()
    end = read_headers(data).end - 1  # the header's terminating zero byte
    many = b"".join(b"a%d\0string\0" % i + struct.pack("<i", 0) for i in range(200_000))
    path.write_bytes(data[:end] + many + data[end:])
    for reader in ("tg.io.read_exr", "tg.io.exr_info"):
        assert_refused(f"{reader}({str(path)!r})", f"more than {MAX_ATTRIBUTES} attributes")
    within = data[:end] + many[: many.index(b"a1000\0")] + data[end:]  # 1000 more: within the budget
    path.write_bytes(within)
    seconds, peak, outcome = run_bounded(f"result = len(tg.io.exr_info({str(path)!r})[0].channels)")
    assert outcome == "3" and seconds <= CPU_SECONDS, (seconds, outcome)  # its headers read; only its offsets moved


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    import struct

    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def _scanline_exr(channels: list, parts: int = 1, extra: int = 0, width: int = 8, height: int = 4,
                  extra_bytes: int = 0) -> bytes:
    """An uncompressed half-float scanline file of zeros, laid out as OpenEXR's file layout document says: ``parts``
    parts (a multi-part file past one) of ``channels`` each, every header with ``extra`` string attributes of
    ``extra_bytes`` bytes."""
    import struct

    box = struct.pack("<4i", 0, 0, width - 1, height - 1)
    chlist = b"".join(name.encode() + b"\0" + struct.pack("<iB3xii", 1, 0, 1, 1) for name in channels) + b"\0"
    multi = parts > 1

    def header(index):
        required = [("channels", "chlist", chlist), ("compression", "compression", b"\0"), ("dataWindow", "box2i", box),
                    ("displayWindow", "box2i", box), ("lineOrder", "lineOrder", b"\0"),
                    ("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
                    ("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0)),
                    ("screenWindowWidth", "float", struct.pack("<f", 1.0))]
        if multi:
            required += [("name", "string", b"part%d" % index), ("type", "string", b"scanlineimage"),
                         ("chunkCount", "int", struct.pack("<i", height))]
        extras = [(f"x{i}", "string", b"x" * extra_bytes) for i in range(extra)]
        return b"".join(_attribute(*entry) for entry in required + extras) + b"\0"

    headers = b"".join(header(index) for index in range(parts)) + (b"\0" if multi else b"")
    line = 2 * width * len(channels)
    chunk = (4 if multi else 0) + 8 + line
    start = 8 + len(headers) + 8 * height * parts
    table = b"".join(struct.pack("<Q", start + n * chunk) for n in range(parts * height))
    chunks = b"".join((struct.pack("<i", n // height) if multi else b"") + struct.pack("<ii", n % height, line) + bytes(line)
                      for n in range(parts * height))
    return struct.pack("<ii", 20000630, 2 | (1 << 12 if multi else 0)) + headers + table + chunks


@pytest.fixture
def header_work(monkeypatch):
    """The attributes the header walk makes, counted; OpenEXR's parser made to fail the test if it is reached."""
    import OpenEXR

    from torchgrade.io.exr import header_bytes

    work = {"attributes": 0}
    made = header_bytes.Attribute

    def counted(*args):
        work["attributes"] += 1
        return made(*args)

    def openexr(*args, **kwargs):
        raise AssertionError("OpenEXR's parser was reached")

    monkeypatch.setattr(header_bytes, "Attribute", counted)
    monkeypatch.setattr(OpenEXR, "File", openexr)
    yield work
    assert OpenEXR.File is openexr


@pytest.mark.parametrize("reader", ["read_exr", "exr_info"])
@pytest.mark.parametrize("case, message", [
    ("100,003 channels", "a part holds more than 4096 channels"),
    ("16 parts of 1,100 channels", "the parts hold more than 16384 channels in all"),
    ("1,024 parts of 1,000 attributes", "the headers hold more than 16384 attributes in all"),
])
def test_an_exr_header_of_too_many_channels_or_attributes_is_refused_before_openexr_parses_it(tmp_path, header_work,
                                                                                              reader, case, message):
    """100,003 channels took 49.5 s to refuse (OpenEXR's parser is quadratic in them), 1,024 parts of 1,000 attributes
    35 s and 1,030 MiB for an 8x4 image: the header walk refuses them by count, before OpenEXR's parser is reached,
    having made at most a budget's worth of attributes (each walk; read_exr walks twice) and under 16 MiB of Python
    objects (the file is mapped, not read)."""
    import tracemalloc

    import torchgrade as tg
    from torchgrade.io.exr.header_bytes import MAX_FILE_ATTRIBUTES

    path = tmp_path / "hostile.exr"
    layout = {"100,003 channels": dict(channels=[f"c{i}" for i in range(100_003)]),
              "16 parts of 1,100 channels": dict(channels=[f"c{i}" for i in range(1100)], parts=16),
              "1,024 parts of 1,000 attributes": dict(channels=list("BGR"), parts=1024, extra=1000)}[case]
    path.write_bytes(_scanline_exr(**layout))
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=message):
            getattr(tg.io, reader)(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert header_work["attributes"] <= 2 * (MAX_FILE_ATTRIBUTES + 1) and peak < 16 << 20, (header_work, peak)


def test_exr_headers_at_their_budgets_are_read(tmp_path):
    """A part of 4,096 channels and a file of 1,024 parts of 5 attributes more than they need: read."""
    import torchgrade as tg

    path = tmp_path / "wide.exr"
    path.write_bytes(_scanline_exr([f"c{i:04d}" for i in range(4096)]))
    assert len(tg.io.exr_info(path)[0].channels) == 4096
    path.write_bytes(_scanline_exr(list("BGR"), parts=1024, extra=5))
    parts = tg.io.exr_info(path)
    assert len(parts) == 1024 and tg.io.read_exr(path, part=1023).shape == (3, 4, 8)


@pytest.mark.parametrize("reader", ["read_exr", "exr_info"])
def test_one_attribute_spanning_the_headers_past_their_byte_budget_is_refused_before_openexr_parses_it(tmp_path,
                                                                                                       header_work, reader):
    """The budget was checked where each attribute starts, so a single attribute of 70 MB passed and OpenEXR's parser
    held 280 MB reading an 8x4 image's headers: where an attribute ends counts."""
    import torchgrade as tg
    from torchgrade.io.exr.header_bytes import MAX_HEADER_BYTES

    path = tmp_path / "one large attribute.exr"
    path.write_bytes(_scanline_exr(list("BGR"), extra=1, extra_bytes=MAX_HEADER_BYTES))
    with pytest.raises(ValueError, match=f"the headers span more than {MAX_HEADER_BYTES} bytes"):
        getattr(tg.io, reader)(path)
    assert header_work["attributes"] <= 2 * 9


def test_exr_headers_at_their_byte_budget_are_read_within_100_mb(tmp_path):
    """OpenEXR's parser holds about four times the headers' bytes: at the budget, an 8x4 image's headers are read
    within 100 MB."""
    from torchgrade.io.exr.header_bytes import MAX_HEADER_BYTES

    path = tmp_path / "large headers.exr"
    path.write_bytes(_scanline_exr(list("BGR"), extra=1, extra_bytes=MAX_HEADER_BYTES - 1024))
    seconds, peak, outcome = run_bounded(f"result = tuple(tg.io.read_exr({str(path)!r}).shape)")
    assert outcome == "(3, 4, 8)" and peak <= 100 << 20 and seconds <= CPU_SECONDS, (seconds, peak, outcome)


# ---------------------------------------------------------------- sizes: one pixel budget


def _huge_png(path, side=10_000) -> None:
    """A valid PNG of ``side`` x ``side`` black pixels (about 300 KB), written a row at a time."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    packer, row, body = zlib.compressobj(9), b"\0" * (1 + 3 * side), []
    for _ in range(side):
        body.append(packer.compress(row))
    body.append(packer.flush())
    header = struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", b"".join(body)) + chunk(b"IEND", b""))


def test_match_refuses_a_png_target_over_the_pixel_budget_from_its_header(tmp_path):
    """A 10000x10000 PNG (300 KB) as ``match``'s target: refused from its header (it took more than 10.3 GB before a
    traceback)."""
    png = tmp_path / "after.png"
    _huge_png(png)
    source = tmp_path / "before.exr"
    code = (f"import torch; tg.io.write_exr({str(source)!r}, torch.rand(3, 8, 8))\n"
            f"from torchgrade.cli import main\n"
            f"result = main(['match', {str(source)!r}, {str(png)!r}, '-o', {str(tmp_path / 'look.json')!r}])")
    seconds, peak, outcome = run_bounded(code)
    assert outcome == "2" and seconds <= CPU_SECONDS and peak <= BYTES, (seconds, peak, outcome)
    with pytest.raises(ValueError, match="pixel budget"):
        from torchgrade.cli.match import read_target

        read_target(png)


def test_demo_refuses_a_scene_over_the_pixel_budget():
    """``demo --width 100000 --height 100000`` tried to allocate 10 GB."""
    seconds, peak, outcome = run_bounded("result = tg.scene.demo_scene(100_000, 100_000)")
    assert outcome.startswith("ValueError") and "pixel budget" in outcome and peak <= BYTES and seconds <= CPU_SECONDS


def test_an_output_pattern_of_a_900_million_digit_frame_number_is_refused(tmp_path):
    """``-o 'x.%0900000000d.png'`` built a 2.9 GB name."""
    plate = tmp_path / "plate.0001.exr"
    code = (f"import torch; tg.io.write_exr({str(plate)!r}, torch.rand(3, 4, 4))\n"
            "from torchgrade.cli import main\n"
            f"result = main(['grade', {str(plate)!r}, '-o', {str(tmp_path / 'x.%0900000000d.png')!r}])")
    seconds, peak, outcome = run_bounded(code)
    assert outcome == "2" and peak <= BYTES and seconds <= CPU_SECONDS, (seconds, peak, outcome)


# ---------------------------------------------------------------- shots never lose a frame


def _plates(folder, count=4):
    import torch

    import torchgrade as tg

    folder.mkdir(exist_ok=True)
    for number in range(1, count + 1):
        tg.io.write_exr(folder / f"plate.{number:04d}.exr", torch.rand(3, 6, 8) * number, half=False)


def test_a_folder_listing_leaves_out_a_killed_writes_temporary_file(tmp_path):
    """A shot killed mid-frame left ``.g.0001.exr.0bc52090.exr`` behind, and a later ``grade out/`` failed on it."""
    from torchgrade.cli import main

    _plates(tmp_path / "out", 2)
    (tmp_path / "out" / ".plate.0001.exr.0bc52090.exr").write_bytes(b"half a frame")
    assert main(["grade", str(tmp_path / "out"), "-o", str(tmp_path / "g.%04d.exr"), "--scene-referred"]) == 0
    assert sorted(p.name for p in tmp_path.glob("g.*.exr")) == ["g.0001.exr", "g.0002.exr"]


def test_a_terminated_shot_leaves_no_temporary_file(tmp_path):
    """SIGTERM in the middle of a shot ends the command as an error does: every write in flight removes its temporary
    file, the frames written are whole, and the status is 143."""
    import signal
    import subprocess
    import sys
    import time

    _plates(tmp_path / "plates", 40)
    script = ("import sys; from torchgrade.cli import main; sys.exit(main(sys.argv[1:]))")
    command = [sys.executable, "-c", script, "grade", str(tmp_path / "plates"), "-o", str(tmp_path / "out" / "g.%04d.exr"),
               "--scene-referred", "--contrast", "10"]
    (tmp_path / "out").mkdir()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.time() + 60
    while not list((tmp_path / "out").glob("g.*.exr")) and time.time() < deadline:
        time.sleep(0.01)
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=60) == 128 + signal.SIGTERM
    assert not [p.name for p in (tmp_path / "out").iterdir() if p.name.startswith(".")]
    import torchgrade as tg

    for frame in (tmp_path / "out").glob("g.*.exr"):
        assert tg.io.read_exr(frame).shape == (3, 6, 8)


def test_overwrite_input_refuses_an_output_pattern_that_names_another_frames_input(tmp_path):
    """With ``--overwrite-input`` an output pattern that names another frame's input (frame 4 of ``plate.1%d.exr`` is
    ``plate.14.exr``, frame 14's input) replaced that input before it was read. Grading each frame in place stays
    allowed."""
    import torch

    import torchgrade as tg
    from torchgrade.cli import main

    folder = tmp_path / "plates"
    folder.mkdir()
    for number in (4, 14):
        tg.io.write_exr(folder / f"plate.{number}.exr", torch.rand(3, 6, 8) * number, half=False)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    frames = [str(folder / "plate.4.exr"), str(folder / "plate.14.exr")]
    assert main(["grade", *frames, "-o", str(folder / "plate.1%d.exr"), "--scene-referred", "--overwrite-input"]) == 2
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    assert main(["grade", *frames, "-o", str(folder / "plate.%d.exr"), "--scene-referred", "--contrast", "20",
                 "--overwrite-input"]) == 0
    assert all((folder / name).read_bytes() != data for name, data in before.items())  # each graded in place
