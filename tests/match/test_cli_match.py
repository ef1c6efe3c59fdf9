"""``torchgrade match``: a look learnt from files, and the door's refusals (one line, exit status 2, no traceback)."""

import json
import struct
import zlib

import pytest
import torch
from bounded import run_bounded

import torchgrade as tg
from torchgrade.cli import main


def test_cli_match_writes_a_readable_look_and_a_cube(tmp_path, capsys):
    source = tg.scene.demo_scene(24, 32)[0]
    tg.io.write_exr(tmp_path / "before.exr", source, half=False)
    target = tg.PostFX(grade={"contrast": 20, "saturation": 15}, tonemap="neutral")(source[None])[0]
    tg.cli.common.write_png(tmp_path / "after.png", target)
    status = main(["match", str(tmp_path / "before.exr"), str(tmp_path / "after.png"), "-o", str(tmp_path / "look.json"),
                   "--cube", str(tmp_path / "look.cube"), "--cube-size", "9", "--tonemap", "neutral", "--tonemap", "aces",
                   "--controls", "contrast,saturation", "--residual", "--steps", "30"])
    assert status == 0
    config = json.loads((tmp_path / "look.json").read_text())
    assert config["tonemap"] == {"mode": "neutral"} and config["grade"]["contrast"] == pytest.approx(20.0, abs=2.0)
    assert tg.io.read_cube(tmp_path / "look.cube").size == 9
    out = capsys.readouterr().out
    assert "match: neutral, 2 controls" in out and "look.cube (9³: " in out
    assert out.splitlines()[-1].startswith("error: ") and "validation colours" in out  # the bake's error report


def chunk(kind: bytes, data: bytes) -> bytes:
    """A PNG chunk: length, type, data, CRC-32 of type and data (PNG specification §5.3)."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png(width: int, height: int, rows=None, crc: bool = True) -> bytes:
    """An 8-bit RGB PNG of ``width`` x ``height``; ``rows`` is its compressed image data (default: black, a row at a
    time, so an 8000x8000 picture is about 200 KB)."""
    if rows is None:
        packer, row = zlib.compressobj(1), b"\0" * (1 + 3 * width)
        rows = b"".join(packer.compress(row) for _ in range(height)) + packer.flush()
    header = chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
    if not crc:
        header = header[:-4] + bytes(4)
    return b"\x89PNG\r\n\x1a\n" + header + chunk(b"IDAT", rows) + chunk(b"IEND", b"")


def refusal(tmp_path, capsys, target: bytes, suffix: str = ".png", source=(135, 240)) -> str:
    """``match`` of a ``source`` (height, width) EXR and ``target``'s bytes: its exit status must be 2 and its one line."""
    tg.io.write_exr(tmp_path / "before.exr", torch.rand(3, *source), half=False)
    (tmp_path / f"after{suffix}").write_bytes(target)
    assert main(["match", str(tmp_path / "before.exr"), str(tmp_path / f"after{suffix}"), "-o", str(tmp_path / "look.json")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "Traceback" not in error and not (tmp_path / "look.json").exists()
    return error


def test_a_png_bomb_target_is_refused_from_its_header(tmp_path, capsys):
    """74 bytes declaring 30000x30000 pixels: PIL raised DecompressionBombError, a traceback, before the budget's check."""
    bomb = png(30000, 30000, rows=zlib.compress(b"\0" * 64))
    assert len(bomb) < 100
    assert "30000x30000 pixels is more than the 67108864-pixel budget" in refusal(tmp_path, capsys, bomb)


def test_a_target_of_another_size_is_refused_before_it_is_decoded(tmp_path, capsys, monkeypatch):
    """An 8000x8000 PNG for a 240x135 source passed the pixel budget and took 2 GB before failing; its header says it
    cannot be the source's picture, so nothing of it is decoded."""
    import PIL.Image

    def no_decoding(*args, **kwargs):
        raise AssertionError("the target was opened for decoding")

    monkeypatch.setattr(PIL.Image, "open", no_decoding)
    error = refusal(tmp_path, capsys, png(8000, 8000))
    assert "is 8000x8000 pixels and the source 240x135" in error and "same size" in error
    tg.io.write_exr(tmp_path / "big.exr", torch.zeros(3, 270, 480), half=True)
    error = refusal(tmp_path, capsys, (tmp_path / "big.exr").read_bytes(), ".exr")
    assert "is 480x270 pixels and the source 240x135" in error


def test_a_large_png_target_is_refused_within_a_small_memory_budget(tmp_path):
    (tmp_path / "after.png").write_bytes(png(8000, 8000))
    code = (f"tg.io.write_exr({str(tmp_path / 'before.exr')!r}, torch.rand(3, 135, 240))\n"
            f"from torchgrade.cli import main\n"
            f"result = main(['match', {str(tmp_path / 'before.exr')!r}, {str(tmp_path / 'after.png')!r}, "
            f"'-o', {str(tmp_path / 'look.json')!r}])")
    seconds, peak, outcome = run_bounded(code, cap_bytes=1 << 30)
    assert outcome == "2" and peak <= 64 << 20, (peak, outcome)  # decoding would take 192 MB of codes alone


NOISE = zlib.compress(b"".join(b"\0" + bytes(torch.randint(0, 256, (72,), generator=torch.Generator().manual_seed(row)).tolist())
                               for row in range(16)))
"""The image data of a 24x16 PNG of noise (filter 0 rows), about 1.2 KB compressed."""


@pytest.mark.parametrize("name, target", [
    ("truncated", png(24, 16, rows=NOISE)[:600]),
    ("garbled image data", png(24, 16, rows=b"\x78\x9c" + bytes(range(256)) * 4)),
    ("a header whose CRC is wrong", png(24, 16, crc=False)),
    ("no PNG at all", b"GIF89a" + bytes(64)),
    ("a zero width", png(0, 16, rows=b"")),
])
def test_a_damaged_png_target_is_one_line(tmp_path, capsys, name, target):
    error = refusal(tmp_path, capsys, target, source=(16, 24))
    assert "after.png" in error, name


@pytest.mark.parametrize("argv, message", [
    (["missing.exr", "after.png", "-o", "look.json"], "missing.exr"),
    (["before.exr", "after.jpg", "-o", "look.json"], "must be an .exr or .png"),
    (["before.exr", "after.png", "-o", "look.txt"], "must end in .json"),
    (["before.exr", "after.png", "-o", "look.json", "--cube", "look.3dl"], "must end in .cube or .clf"),
    (["before.exr", "after.png", "-o", "look.json", "--scene-referred", "--residual"], "need a display-referred target"),
])
def test_cli_match_bad_inputs_print_one_line(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    tg.io.write_exr(tmp_path / "before.exr", torch.rand(3, 4, 4), half=False)
    tg.cli.common.write_png(tmp_path / "after.png", torch.rand(3, 4, 4))
    assert main(["match", *argv]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and message in error and "Traceback" not in error
