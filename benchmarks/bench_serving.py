"""The serving example under load: p50/p99 latency and the replica's memory with 16 clients sending real frames, and
a normal client's latency while 24 connections trickle their bodies.

    .venv/bin/python -m benchmarks serving [--quick] [--out DIR] [--requests 64] [--memory-mib 4096] [--threads N]

Runs the example as its users run it: ``examples/serving/serve.py`` in a process of its own (its own Ray) on a free
loopback port, serving the cinematic look (``export/looks/cinematic.json``) exported with a float32 NHWC input and
8-bit sRGB output, with its default limits but ``--memory-mib``; ``examples/serving/client.py`` sends the load, twice:

* **real frames**: ``--requests`` requests from 16 client threads, each taking the next file in turn: sample EXRs
  (Desk, CandleGlass, GoldenGate, Carrots, BrightRings, WideColorGamut) and an 8-bit PNG of each (its sRGB codes);
  latency p50, p99 and max as the client sees it, the statuses, and the server's ``/stats``: the replica's peak
  resident memory against its budget, the most memory requests held at once, how many requests waited for it.
* **slow clients**: one client sending the smallest PNG 20 times in turn while 24 connections trickle a frame a byte
  every 0.1 s (each reconnecting when answered): its latency and statuses, and the trickling connections' answers.

``--quick``: 16 requests of the three smallest files and their PNGs, 8 in the slow phase. Writes ``serving.json`` and
``serving.md`` to ``--out``. Latencies depend on the machine and its load: the environment line records both.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import torch

import torchgrade as tg
from benchmarks.common import EXR_DIR, ROOT, argument_parser, mark_table, write_results
from benchmarks.suite.stamp import source_commit

EXAMPLE = ROOT / "examples" / "serving"
FILES = ("Desk", "CandleGlass", "GoldenGate", "Carrots", "BrightRings", "WideColorGamut")
QUICK_FILES = ("Carrots", "BrightRings", "WideColorGamut")
QUICK = "16 requests of the three smallest sample files and their PNGs, 8 in the slow phase"
CLIENTS, TRICKLERS = 16, 24


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _get_json(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=10.0) as answer:
        return json.loads(answer.read())


def real_frames(names: tuple, folder: Path) -> list:
    """Each sample EXR and a PNG of its sRGB codes written to ``folder``: the paths, EXRs first."""
    from PIL import Image

    pngs = []
    for name in names:
        light = tg.io.read_exr(EXR_DIR / f"{name}.exr", to_rec709=True)[:3]
        codes = tg.onnx.model_input(light[None], tg.onnx.frame_format(torch.uint8, "NHWC"))[0].numpy()
        pngs.append(folder / f"{name}.png")
        Image.fromarray(codes, "RGB").save(pngs[-1])
    return [EXR_DIR / f"{name}.exr" for name in names] + pngs


class Server:
    """``serve.py`` serving ``model`` in a process of its own, stopped (SIGTERM, as a user stops it) on leaving."""

    def __init__(self, model: Path, flags: list):
        self.url = f"http://127.0.0.1:{_free_port()}"
        self.process = subprocess.Popen([sys.executable, str(EXAMPLE / "serve.py"), str(model), "--port",
                                         self.url.rsplit(":", 1)[1], *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def __enter__(self) -> "Server":
        deadline = time.monotonic() + 600
        while True:
            try:
                _get_json(self.url + "/stats")
                return self
            except OSError as error:
                if self.process.poll() is not None or time.monotonic() > deadline:
                    self.__exit__()
                    raise RuntimeError(f"serve.py did not start: {self.process.stderr.read().decode()[-2000:]}") from error
                time.sleep(0.5)

    def __exit__(self, *_) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(120)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()

    def client(self, flags: list, out: Path) -> dict:
        """``client.py``'s figures for a run with ``flags``."""
        subprocess.run([sys.executable, str(EXAMPLE / "client.py"), self.url, *flags, "--json", str(out)], check=True,
                       stdout=subprocess.DEVNULL)
        return json.loads(out.read_text())


def load_table(results: dict) -> list:
    """Each phase's requests, statuses and latencies as the clients saw them, and the replica's peak memory."""
    lines = ["| phase | requests | clients | statuses | p50 ms | p99 ms | max ms | trickling answers |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for phase in ("real_frames", "slow_clients"):
        run = results[phase]
        lines.append(f"| {phase.replace('_', ' ')} | {run['requests']} | {run['concurrency']} | {run['statuses']} | "
                     f"{run['latency_ms_p50']} | {run['latency_ms_p99']} | {run['latency_ms_max']} | "
                     f"{run['slow_answers'] or '-'} |")
    peak = results["real_frames"]["server"]["peak_rss_mib"]
    return lines + ["", f"Replica peak resident memory {peak} MiB of its {results['memory_mib']} MiB budget."]


def markdown(results: dict) -> list:
    server = results["real_frames"]["server"]
    lines = ["# The serving example under load", "",
             f"`{results['command']}` at `{results['commit']}`{' (modified)' if results['modified'] else ''}: the cinematic "
             f"look, float32 NHWC in, sRGB 8-bit out; replica memory budget {results['memory_mib']} MiB "
             f"(idle {results['model']['idle_mib']} MiB).", "",
             *mark_table("serving", "load", load_table(results))]
    memory = server["memory"]
    lines += ["", f"Requests held at most {memory['held_peak_mib']} MiB at once; {memory['waited']} waited for memory. "
              f"Measured costs (fixed MiB, bytes a pixel): {results['model']['costs']}.",
              "Files: " + ", ".join(f"{name} ({size // 1024} KiB)" for name, size in results["files"].items()) + "."]
    return lines


def main(argv=None) -> None:
    parser = argument_parser(__doc__, QUICK)
    parser.add_argument("--requests", type=int, default=64, help="requests of the real-frames phase")
    parser.add_argument("--memory-mib", type=int, default=4096, help="the replica's memory budget")
    parser.add_argument("--threads", type=int, help="onnxruntime threads per batch (default: one per core)")
    args = parser.parse_args(argv)
    requests, slow_requests = (16, 8) if args.quick else (args.requests, 20)
    command = ".venv/bin/python -m benchmarks serving" + (" --quick" if args.quick else f" --requests {requests}") + \
        f" --memory-mib {args.memory_mib}" + (f" --threads {args.threads}" if args.threads else "") + f" --out {args.out}"
    with tempfile.TemporaryDirectory(prefix="torchgrade-bench-serving-") as folder:
        folder = Path(folder)
        look = tg.PostFX.from_config(ROOT / "export" / "looks" / "cinematic.json").eval()
        model = tg.onnx.export(look, folder / "look.onnx", input_dtype=torch.float32, layout="NHWC", output="srgb8")
        files = real_frames(QUICK_FILES if args.quick else FILES, folder)
        flags = ["--memory-mib", str(args.memory_mib)] + (["--threads", str(args.threads)] if args.threads else [])
        with Server(model, flags) as server:
            loaded = server.client(["--frames", str(requests), "--concurrency", str(CLIENTS),
                                    *[flag for path in files for flag in ("--image", str(path))]], folder / "load.json")
            smallest = min(files, key=lambda path: path.stat().st_size if path.suffix == ".png" else float("inf"))
            slow = server.client(["--frames", str(slow_requests), "--concurrency", "1", "--image", str(smallest),
                                  "--slow", str(TRICKLERS)], folder / "slow.json")
            served = _get_json(server.url + "/model")
        results = {"command": command, **source_commit(), "quick": args.quick, "memory_mib": args.memory_mib, "model": served,
                   "files": {path.name: path.stat().st_size for path in files}, "real_frames": loaded, "slow_clients": slow}
    write_results(args.out, "serving", results, markdown(results), command)


if __name__ == "__main__":
    main()
