"""Peak memory of ``read_exr`` against the tensor it returns, on the largest sample files and on
4096×4096 files this script writes with the OpenEXR bindings: RGB half, RGB float, and
luminance/chroma (Y full, RY and BY 2×2-subsampled, half).

Each read runs in a fresh Python process: the kernel's peak-resident counter (``VmHWM``) is reset
after the imports, and the peak it reaches during the read, minus the resident memory before it,
is divided by the returned tensor's bytes. Each file is read twice so: as the first read of the
process, and after a warm-up read of two 16×16 files (RGB half and luminance/chroma), which pages in
the library code and starts torch's threads, the fixed costs of a process's first read. Writes
``exr_memory.json`` and ``exr_memory.md`` to ``--out`` (default benchmarks/out; the committed ones with
``--out benchmarks/results``).

Run: ``.venv/bin/python -m benchmarks exr_memory [--out DIR]`` (Linux)
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

from benchmarks.common import EXR_DIR, argument_parser, write_results

ROOT = Path(__file__).resolve().parents[1]

COMMAND = ".venv/bin/python -m benchmarks exr_memory"
SIZE = 4096
SAMPLES = [("formats/Adjuster.exr", {}), ("GoldenGate.exr", {}), ("formats/beachball_multipart.0001.exr", {}),
           ("formats/beachball_multipart.0001.exr", {"part": 1, "layer": ""}), ("formats/beachball_multipart.0001.exr", {"view": "left"}),
           ("formats/beachball_multipart.0001.exr", {"layer": "disparityR"}), ("CandleGlass.exr", {}), ("Desk.exr", {}),
           ("formats/beachball_singlepart.0001.exr", {}), ("formats/Rec709_YC.exr", {})]
"""The sample files from the largest down, luminance/chroma's one sample last; the multi-part stereo
frame also by its later parts (1: depth_left's Z; the left view's RGBA in part 4; disparityR in part 8)."""

_READ = """
import json, sys, time
import torchgrade as tg
import OpenEXR  # the bindings, which load at a process's first read: paid once, outside the measurement
from benchmarks.common import status_kib
for warm_up in sys.argv[4:]:
    tg.io.read_exr(warm_up)
with open("/proc/self/clear_refs", "w") as clear:
    clear.write("5")  # resets the peak (VmHWM) to the resident size now
before, code = status_kib("VmRSS"), status_kib("RssFile")
start = time.process_time()
image = tg.io.read_exr(sys.argv[1], **json.loads(sys.argv[2])) if sys.argv[3] == "read" else tg.io.exr_info(sys.argv[1])
cpu = time.process_time() - start
shape, size = (tuple(image.shape), image.numel() * 4 / 2**20) if sys.argv[3] == "read" else ("-", 0)
print(shape, size, (status_kib("VmHWM") - before) / 1024, cpu,
      (status_kib("RssFile") - code) / 1024, sep="\\t")
"""


def peak_of_read(path: Path, options: dict, step: str = "read", warm_ups: tuple = ()) -> dict:
    """Shape, returned MiB, peak MiB above the resident memory before the read, their ratio, and the
    MiB of library code and data files paged in meanwhile (``RssFile``: part of the peak, paid once
    a process). ``step="open"`` measures ``exr_info`` alone: the headers every read starts with.
    ``warm_ups``: files read first in the same process, outside the measurement."""
    line = subprocess.run([sys.executable, "-c", _READ, str(path), json.dumps(options), step, *map(str, warm_ups)], capture_output=True, text=True,
                          check=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT)}).stdout.strip().splitlines()[-1]
    shape, returned, peak, cpu, code = line.split("\t")
    return {"shape": shape, "returned_mib": round(float(returned), 1), "peak_mib": round(float(peak), 1),
            "ratio": round(float(peak) / float(returned), 2) if float(returned) else None, "code_mib": round(float(code), 1),
            "cpu_seconds": round(float(cpu), 2)}


def write_files(folder: Path, size: int) -> dict[str, Path]:
    """``size``² RGB half, RGB float and luminance/chroma files of smooth noise (ZIP compressed)."""
    rng = np.random.default_rng(0)
    block = max(1, size // 64)
    rgb = (rng.random((3, size // block, size // block)) * 4).repeat(block, axis=1).repeat(block, axis=2) + rng.random((3, size, size)) * 0.1
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    paths = {name: folder / f"{name}.exr" for name in (f"rgb_half_{size}", f"rgb_float_{size}", f"yc_{size}")}
    for name, dtype in ((f"rgb_half_{size}", np.float16), (f"rgb_float_{size}", np.float32)):
        OpenEXR.File(header, {c: rgb[i].astype(dtype) for i, c in enumerate("RGB")}).write(str(paths[name]))
    y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
    # the bindings take subsampled channels at full size and store the samples at even coordinates
    chroma = {name: ((rgb[i] - y) / y).astype(np.float16) for name, i in (("RY", 0), ("BY", 2))}
    channels = {"Y": y.astype(np.float16), **{name: OpenEXR.Channel(c, 2, 2) for name, c in chroma.items()}}
    OpenEXR.File(header, channels).write(str(paths[f"yc_{size}"]))
    return paths


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        small = write_files(Path(folder), 16)
        warm_ups = (small["rgb_half_16"], small["yc_16"])
        reads = [(name + "".join(f", {key}={value!r}" for key, value in options.items()), EXR_DIR / name, options)
                 for name, options in SAMPLES] + [(name, path, {}) for name, path in write_files(Path(folder), SIZE).items()]
        results = {name: {**peak_of_read(path, options), "warm": peak_of_read(path, options, warm_ups=warm_ups)}
                   for name, path, options in reads}
    opening = {name: peak_of_read(EXR_DIR / name, {}, "open") for name in ("formats/Rec709_YC.exr", "Desk.exr")}
    rows = [f"| {name} | {r['shape']} | {r['returned_mib']} | {r['peak_mib']} | {r['ratio']} | {r['code_mib']} | "
            f"{r['warm']['peak_mib']} | {r['warm']['ratio']} | {r['cpu_seconds']} |" for name, r in results.items()]
    table = ["| file, options | returned shape | returned MiB | first read: peak MiB | peak / returned | code paged in MiB | "
             "after a warm-up read: peak MiB | peak / returned | CPU s |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |", *rows]
    opened = ", ".join(f"{name} {r['peak_mib']} MiB ({r['code_mib']} MiB of it code)" for name, r in opening.items())
    text = ("Peak memory of `tg.io.read_exr(path, **options)`, one fresh process per read:\n\n" + "\n".join(table) + "\n\n"
        "Code paged in is the growth of the process's file-backed resident memory (`RssFile`) during the read: "
        "the OpenEXR and torch library code that the first read in a process touches, counted in the peak "
        "and paid once a process (a second read of the same file adds none). It is most of the fixed cost that "
        "makes small files' ratios high; the warm-up columns read the file after two 16×16 files (RGB half and "
        "luminance/chroma) in the same process, which pay it. Opening a file alone (`tg.io.exr_info`, the headers every read starts "
        f"with) peaks at: {opened}.\n\n"
        "CPU s is the reading process's CPU time on the first read; it depends on the machine's load. "
        f"Read the memory columns.\n\nCommand: `{COMMAND}`")
    write_results(args.out, "exr_memory", {"reads": results, "opening": opening}, text.splitlines(), COMMAND)


if __name__ == "__main__":
    main()
