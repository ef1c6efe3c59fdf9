"""Fuzzing the files and configs torchgrade reads and writes: seeded mutations, each given a verdict.

Four families, each a function ``verdicts(count, seed) -> Counter``:

* ``exr``: sample EXRs (small ones) with bytes of their headers and chunk tables changed, inserted or cut, read
  by :func:`torchgrade.io.read_exr` in a child process (a crash or a hang there is a verdict, not the end of the
  run);
* ``cube``: a small valid ``.cube`` (a 17-entry shaper and a 3³ table) with a random cut, insertion, truncation
  or one number swapped for an extreme one, read by :func:`torchgrade.io.read_cube`, and an accepted LUT looked
  up on extreme pixels;
* ``clf``: a LUT written by :func:`torchgrade.io.write_clf` with a random title and entries, parsed as XML;
* ``config``: ``export/looks/cinematic.json`` with a value replaced, removed or added at a random place, built by
  :meth:`torchgrade.PostFX.from_config` and run on extreme pixels.

Verdicts: ``"refused"`` (the documented ``ValueError``), ``"accepted"`` (read, built or written, and what came out
finite), and any other is a defect: the exception's name, ``"non-finite"``, ``"crashed"`` or ``"hung"``. The suite
runs a few hundred of each (``tests/library/test_fuzz.py``); ``benchmarks/robustness.py --fuzz`` runs thousands and commits
the counts.

Examples:
    >>> verdicts = FAMILIES["config"](5, seed=0)
    >>> set(verdicts) <= {"refused", "accepted"}
    True
"""

from __future__ import annotations

import collections
import json
import random
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import torch

import torchgrade as tg

ROOT = Path(__file__).resolve().parents[1]
EXR_DIR = ROOT.parent / "shared" / "data" / "exr"
FUZZED_EXRS = ("GrayRampsHorizontal.exr", "AllHalfValues.exr", "WideFloatRange.exr", "BrightRings.exr")
"""Small sample EXRs (18 to 151 KB): scan lines, several compressions, half and float."""
EXR_HEAD_BYTES = 2048
"""Mutations fall in a file's first bytes: the header and the chunk table, where a reader decides what to allocate."""
EXTREME_PIXELS = torch.tensor([0.0, 1e-45, 0.18, 1.0, 60.0, 65504.0, -1.0, 3e38]).repeat(3, 1).reshape(1, 3, 2, 4)

_TOKENS = (b"\x00", b"\xff", b"\xff\xff\xff\x7f", b"\x00\x00\x00\x80", b"\x01\x00\x00\x00", b"box2i", b"channels", b"tiledesc",
           b"dataWindow", b"displayWindow", b"compression", b"chlist", b"\x10\x00\x00\x00", b"9" * 12)


def mutated(rng: random.Random, valid: bytes, tokens, region: int) -> bytes:
    """``valid`` with a random cut, insertion of tokens, byte flips or truncation inside its first ``region`` bytes."""
    start = rng.randrange(min(len(valid), region) + 1)
    kind = rng.randrange(4)
    if kind == 0:  # flip a few bytes
        data = bytearray(valid)
        for position in rng.sample(range(start, min(len(valid), start + 16) or 1), k=min(3, max(1, len(valid) - start))):
            if position < len(data):
                data[position] = rng.randrange(256)
        return bytes(data)
    if kind == 1:  # truncate
        return valid[:start]
    end = min(len(valid), start + rng.randrange(24))
    insert = b"".join(rng.choice(tokens) for _ in range(rng.randrange(1, 4)))
    return valid[:start] + insert + (valid[end:] if kind == 2 else valid[start:])


_EXR_CHILD = """
import sys, signal, pathlib, torch, torchgrade as tg
for path in sys.argv[1:]:
    signal.alarm(20)
    try:
        image = tg.io.read_exr(path)
        print('VERDICT accepted' if image.numel() <= 2 ** 28 else 'VERDICT oversized', flush=True)
    except ValueError:
        print('VERDICT refused', flush=True)
    except Exception as error:
        print('VERDICT ' + type(error).__name__, flush=True)
    signal.alarm(0)
"""


def exr_verdicts(count: int, seed: int = 0) -> collections.Counter:
    """Verdicts on ``count`` mutated EXRs, read in child processes (one per batch; a crash ends only its batch)."""
    rng = random.Random(seed)
    valid = [(EXR_DIR / name).read_bytes() for name in FUZZED_EXRS]
    verdicts = collections.Counter()
    with tempfile.TemporaryDirectory() as folder:
        paths = []
        for index in range(count):
            path = Path(folder) / f"{index}.exr"
            path.write_bytes(mutated(rng, rng.choice(valid), _TOKENS, EXR_HEAD_BYTES))
            paths.append(str(path))
        for batch in (paths[i:i + 50] for i in range(0, len(paths), 50)):
            try:
                done = subprocess.run([sys.executable, "-c", _EXR_CHILD, *batch], capture_output=True, text=True, timeout=30 * len(batch))
            except subprocess.TimeoutExpired:
                verdicts["hung"] += len(batch)
                continue
            lines = [line.split(" ", 1)[1] for line in done.stdout.splitlines() if line.startswith("VERDICT ")]
            verdicts.update(lines)
            if len(lines) < len(batch):
                verdicts["crashed" if done.returncode < 0 else f"exit {done.returncode}"] += 1
                verdicts["unread (after a crash)"] += len(batch) - len(lines) - 1
    return verdicts


_CUBE_TOKENS = (b"LUT_3D_SIZE", b"LUT_1D_SIZE", b"DOMAIN_MIN", b"DOMAIN_MAX", b"TITLE", b"nan", b"inf", b"-1", b"257", b"1e400",
                b"3.4e38", b"-3e38", b"\x00", b"\n", b"\r", b"x", b"\xef\xbb\xbf", b"\xc3\xa9", b"9" * 30)


_CUBE_NUMBERS = (b"0", b"-0", b"1e-45", b"0.18", b"-1", b"60", b"65504", b"1e6", b"1.5e6", b"2.5e9", b"1e30", b"3.4e38",
                 b"-3.4e38", b"1e39", b"nan", b"-inf", b"3", b"65", b"1e-9")


def number_swapped(rng: random.Random, valid: bytes, numbers) -> bytes:
    """``valid`` with one of its whitespace-separated fields (a number, mostly) replaced by one of ``numbers``."""
    pieces = re.split(rb"(\s+)", valid)  # fields at even places, the spaces between them at odd ones
    pieces[2 * rng.randrange((len(pieces) + 1) // 2)] = rng.choice(numbers)
    return b"".join(pieces)


def cube_verdicts(count: int, seed: int = 0) -> collections.Counter:
    """Verdicts on ``count`` mutated ``.cube`` files; an accepted LUT must look up extreme pixels to finite values."""
    rng = random.Random(seed)
    verdicts = collections.Counter()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "valid.cube"
        lut = tg.bake_lut(lambda x: x * 0.5, size=3, shaper="logc", report_tolerance=float("inf"))
        tg.io.write_cube(path, lut, shaper_size=17)
        valid = path.read_bytes()
        for _ in range(count):
            swap = rng.random() < 0.5
            path.write_bytes(number_swapped(rng, valid, _CUBE_NUMBERS) if swap else mutated(rng, valid, _CUBE_TOKENS, len(valid)))
            verdicts[_verdict(lambda: _finite(tg.io.read_cube(path)(EXTREME_PIXELS, rng.choice(tg.lut.INTERPOLATIONS))))] += 1
    return verdicts


def clf_verdicts(count: int, seed: int = 0) -> collections.Counter:
    """Verdicts on ``count`` CLF writes of random titles and entries; a written file must parse as XML with its LUT."""
    rng = random.Random(seed)
    alphabet = "abc XYZ 0129 é日\t\r\n\x00\x07\x1b<>&\"'" + chr(0xFFFE) + chr(0x1F600)
    verdicts = collections.Counter()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "look.clf"
        for _ in range(count):
            title = "".join(rng.choice(alphabet) for _ in range(rng.randrange(0, 12)))
            scale = rng.choice((1.0, 65504.0, 1e5, float("nan")))
            table = torch.rand(3, 3, 3, 3, generator=torch.Generator().manual_seed(rng.randrange(2**31))) * scale

            def write_and_parse(table=table, title=title):
                tg.io.write_clf(path, tg.LUT3D(table), title=title)
                root = ElementTree.parse(path).getroot()
                return root.find("LUT3D") is not None

            verdicts[_verdict(write_and_parse)] += 1
    return verdicts


_CONFIG_VALUES = (0, -1, 1e-45, 0.5, 60.0, 65504.0, 1e30, -1e300, int("9" * 400), "high", True, None, [], [1, 2], [[1]], {}, {"x": 1},
                  [0.5] * 3, [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "aces", "log")


def config_verdicts(count: int, seed: int = 0) -> collections.Counter:
    """Verdicts on ``count`` edits of the cinematic look's config; a look that builds must grade extreme pixels finitely."""
    rng = random.Random(seed)
    base = json.loads((ROOT / "export" / "looks" / "cinematic.json").read_text())
    verdicts = collections.Counter()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "look.json"
        for _ in range(count):
            path.write_text(json.dumps(_edited(rng, json.loads(json.dumps(base)))))
            verdicts[_verdict(lambda: _finite(tg.PostFX.from_config(path)(EXTREME_PIXELS)))] += 1
    return verdicts


def _edited(rng: random.Random, config: dict) -> dict:
    """``config`` with one value replaced, one key removed or one unknown key added, at a random depth."""
    holder = config
    while True:
        key = rng.choice(list(holder)) if holder else None
        if key is None or not isinstance(holder[key], dict) or rng.random() < 0.3:
            break
        holder = holder[key]
    edit = rng.randrange(3)
    if edit == 0 and key is not None:
        holder[key] = rng.choice(_CONFIG_VALUES)
    elif edit == 1 and key is not None:
        del holder[key]
    else:
        holder[rng.choice(("grade", "contrast", "mode", "sharpen", "lut"))] = rng.choice(_CONFIG_VALUES)
    return config


def _finite(out) -> bool:
    return bool(torch.isfinite(out).all()) if isinstance(out, torch.Tensor) else bool(out)


def _verdict(attempt) -> str:
    try:
        return "accepted" if attempt() else "non-finite"
    except ValueError:
        return "refused"
    except Exception as error:  # noqa: BLE001 - any other exception is the finding
        return type(error).__name__


FAMILIES = {"exr": exr_verdicts, "cube": cube_verdicts, "clf": clf_verdicts, "config": config_verdicts}
"""Each fuzzed family's verdict function."""

DEFECTS_FREE = {"refused", "accepted"}
"""The verdicts that are not defects."""
