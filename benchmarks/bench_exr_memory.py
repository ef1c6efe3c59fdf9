"""Peak memory of ``read_exr`` against the tensor it returns, on the largest sample files and on
4096×4096 files this script writes with the OpenEXR bindings: RGB half, RGB float, and
luminance/chroma (Y full, RY and BY 2×2-subsampled, half).

Each read runs in a fresh Python process: the kernel's peak-resident counter (``VmHWM``) is reset
after the imports, and the peak it reaches during the read, minus the resident memory before it,
is divided by the returned tensor's bytes. Writes ``results/exr_memory.json`` and ``results/exr_memory.md``.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_exr_memory.py`` (Linux)
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.common import EXR_DIR  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SIZE = 4096
SAMPLES = ["formats/Adjuster.exr", "GoldenGate.exr", "formats/beachball_multipart.0001.exr", "CandleGlass.exr", "Desk.exr",
           "formats/beachball_singlepart.0001.exr", "formats/Rec709_YC.exr"]
"""The sample files from the largest down, luminance/chroma's one sample last."""

_READ = """
import sys, time
import torchgrade as tg
from benchmarks.common import status_kib
with open("/proc/self/clear_refs", "w") as clear:
    clear.write("5")  # resets the peak (VmHWM) to the resident size now
before = status_kib("VmRSS")
start = time.process_time()
image = tg.io.read_exr(sys.argv[1])
cpu = time.process_time() - start
print(tuple(image.shape), image.numel() * 4 / 2**20, (status_kib("VmHWM") - before) / 1024, cpu, sep="\\t")
"""


def peak_of_read(path: Path) -> dict:
    """Shape, returned MiB, peak MiB above the resident memory before the read, and their ratio."""
    line = subprocess.run([sys.executable, "-c", _READ, str(path)], capture_output=True, text=True, check=True, cwd=ROOT,
                          env={"PYTHONPATH": str(ROOT)}).stdout.strip().splitlines()[-1]
    shape, returned, peak, cpu = line.split("\t")
    return {"shape": shape, "returned_mib": round(float(returned), 1), "peak_mib": round(float(peak), 1),
            "ratio": round(float(peak) / float(returned), 2), "cpu_seconds": round(float(cpu), 2)}


def write_large(folder: Path) -> dict[str, Path]:
    """4096² RGB half, RGB float and luminance/chroma files of smooth noise (ZIP compressed)."""
    rng = np.random.default_rng(0)
    rgb = (rng.random((3, SIZE // 64, SIZE // 64)) * 4).repeat(64, axis=1).repeat(64, axis=2) + rng.random((3, SIZE, SIZE)) * 0.1
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    paths = {name: folder / f"{name}.exr" for name in ("rgb_half_4096", "rgb_float_4096", "yc_4096")}
    for name, dtype in (("rgb_half_4096", np.float16), ("rgb_float_4096", np.float32)):
        OpenEXR.File(header, {c: rgb[i].astype(dtype) for i, c in enumerate("RGB")}).write(str(paths[name]))
    y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
    # the bindings take subsampled channels at full size and store the samples at even coordinates
    chroma = {name: ((rgb[i] - y) / y).astype(np.float16) for name, i in (("RY", 0), ("BY", 2))}
    channels = {"Y": y.astype(np.float16), **{name: OpenEXR.Channel(c, 2, 2) for name, c in chroma.items()}}
    OpenEXR.File(header, channels).write(str(paths["yc_4096"]))
    return paths


def main() -> None:
    results = {name: peak_of_read(EXR_DIR / name) for name in SAMPLES}
    with tempfile.TemporaryDirectory() as folder:
        for name, path in write_large(Path(folder)).items():
            results[name] = peak_of_read(path)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "exr_memory.json").write_text(json.dumps(results, indent=2) + "\n")
    rows = [f"| {name} | {r['shape']} | {r['returned_mib']} | {r['peak_mib']} | {r['ratio']} | {r['cpu_seconds']} |"
            for name, r in results.items()]
    table = ["| file | returned shape | returned MiB | peak MiB | peak / returned | CPU s |",
             "| --- | --- | --- | --- | --- | --- |", *rows]
    (RESULTS / "exr_memory.md").write_text("Peak memory of `tg.io.read_exr(path)` (default arguments), one fresh process per read:\n\n"
                                           + "\n".join(table) + "\n\nCPU s is the reading process's CPU time. On a machine shared with other jobs it swings by "
                                           "10x from run to run: luminance/chroma runs many strip-sized operations, and torch's "
                                           "threads wait on each other when the cores are busy (4096² luminance/chroma: 2.3 s wall "
                                           "with OMP_NUM_THREADS=1, 29.5 s with 2, at a load of 4.5 on 2 cores). Read the memory columns.\n\n"
                                           "Command: `PYTHONPATH=. .venv/bin/python benchmarks/bench_exr_memory.py`\n")
    print("\n".join(table))


if __name__ == "__main__":
    main()
