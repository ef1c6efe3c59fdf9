"""A small batching server for a torchgrade ONNX model: the standard library's HTTP server, a queue, one worker thread
and onnxruntime.

    python examples/serving/server.py look.onnx [--port 8000] [--max-batch 8] [--wait-ms 5] [--max-pending 64] [--device cuda]

Endpoints:

* ``POST /frame``: a raw frame (format below); the answer is the graded frame, same format.
* ``POST /image``: the bytes of a PNG (8-bit RGB/RGBA, sRGB) or OpenEXR file (linear); the answer is the graded frame.
  The file is decoded to linear light and given to the model as its input takes it (integer inputs: sRGB codes).
* ``GET /stats``: JSON: requests, frames, batches, mean batch size, rejected (503), latency p50/p99 ms and throughput
  frames/s over the last 1000 frames, pending frames, resident memory (MiB).
* ``GET /model``: JSON: the model's frame format (input dtype, output dtype) and the server's settings.

**Frame format** (little-endian): a 16-byte header, ``b"TGF1"``, ``uint32`` height, ``uint32`` width, the numpy
dtype string of the samples (``"|u1"``, ``"<u2"``, ``"<f2"``, ``"<f4"``) NUL-padded to 4 bytes; then
``height * width * 3`` samples, RGB interleaved, rows top first: one ``(height, width, 3)`` array, as decoders
and render targets give frames. A request's dtype is the model's input dtype (``GET /model``); the answer's is its
output dtype. Export with ``layout="NHWC"`` and the frames go to the model as they come; an NCHW model gets them
transposed here.

**Batching.** Requests wait in a queue; the worker takes the first, waits up to ``--wait-ms`` for more, up to
``--max-batch`` frames, groups them by size and runs each group as one batch. Batching pays where a call has a
fixed cost to spread, as on a GPU; on a CPU a frame already runs on every core, and a batch leaves the cache: on two
shared cores (a grade + ACES look, uint8 NHWC in and out) 64x64 frames ran at 293 frames/s unbatched and 238 in
batches of up to 8, 256x256 at 120 and 71, 1080p at 3.9 and 3.3. **Bounded memory**: at most
``--max-pending`` frames are admitted at once (waiting or in a batch); a request beyond that is answered 503 at once,
a body over ``--max-bytes`` 413, a malformed one 400.

A look with eye adaptation serves stills: the model's ``adapted`` and ``dt`` inputs are left to their defaults
(instant adaptation); every input but the image must have a default (``tg.onnx.export``'s ``optional_inputs=True``).
"""

from __future__ import annotations

import argparse
import collections
import io
import json
import os
import queue
import resource
import signal
import struct
import sys
import tempfile
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Optional

import numpy as np
import torch

import torchgrade as tg

HEADER = struct.Struct("<4sII4s")
MAGIC = b"TGF1"
DTYPES = {np.dtype(name).str: np.dtype(name) for name in ("uint8", "uint16", "float16", "float32")}
WINDOW = 1000
"""Frames the latency and throughput figures of ``/stats`` are taken over (the most recent)."""


def pack_frame(frame: np.ndarray) -> bytes:
    """A ``(height, width, 3)`` array in the frame format.

    Examples:
        >>> body = pack_frame(np.zeros((2, 3, 3), np.uint8))
        >>> len(body), unpack_frame(body).shape
        (34, (2, 3, 3))
    """
    frame = np.ascontiguousarray(frame)
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype.newbyteorder("<").str not in DTYPES:
        raise ValueError(f"a frame is a (height, width, 3) array of {sorted(DTYPES)}, got {frame.shape} {frame.dtype}")
    frame = frame.astype(frame.dtype.newbyteorder("<"), copy=False)
    return HEADER.pack(MAGIC, frame.shape[0], frame.shape[1], frame.dtype.str.encode()) + frame.tobytes()


def unpack_frame(body: bytes) -> np.ndarray:
    """The ``(height, width, 3)`` array of a frame-format body; ``ValueError`` naming what is wrong.

    Examples:
        >>> unpack_frame(b"TGF1" + bytes(12))
        Traceback (most recent call last):
        ...
        ValueError: frame of 0x0 pixels
    """
    if len(body) < HEADER.size:
        raise ValueError(f"a frame starts with a {HEADER.size}-byte header, got {len(body)} bytes")
    magic, height, width, dtype = HEADER.unpack_from(body)
    if magic != MAGIC:
        raise ValueError(f"a frame starts with {MAGIC!r}, got {magic!r}")
    if not height or not width:
        raise ValueError(f"frame of {height}x{width} pixels")
    dtype = DTYPES.get(dtype.rstrip(b"\0").decode("ascii", "replace"))
    if dtype is None:
        raise ValueError(f"frame dtype must be one of {sorted(DTYPES)}")
    expected = HEADER.size + height * width * 3 * dtype.itemsize
    if len(body) != expected:
        raise ValueError(f"a {height}x{width} {dtype} frame is {expected} bytes, got {len(body)}")
    return np.frombuffer(body, dtype, offset=HEADER.size).reshape(height, width, 3)


def resident_mib() -> float:
    """This process's resident memory in MiB (``/proc/self/statm``; elsewhere its peak, from ``getrusage``)."""
    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / 2**20 if sys.platform == "darwin" else peak / 1024


class Busy(Exception):
    """More frames are pending than the server admits (HTTP 503)."""


class _Job:
    def __init__(self, frame: np.ndarray):
        self.frame, self.result, self.error = frame, None, None
        self.started, self.done = time.perf_counter(), threading.Event()


class Batcher:
    """Runs frames submitted from many threads as batches on one onnxruntime session (see the module docstring)."""

    def __init__(self, runner, max_batch: int = 8, wait_ms: float = 5.0, max_pending: int = 64):
        fmt = tg.onnx.read_frame_format(runner.get_modelmeta().custom_metadata_map)
        required = [port.name for port in runner.get_inputs()[1:] if not port.type.startswith("optional")]
        if required:
            raise ValueError(f"this server feeds the image alone; the model requires {required}: export it with optional inputs")
        if max_batch < 1 or max_pending < 1 or wait_ms < 0:
            raise ValueError(f"max_batch and max_pending must be >= 1 and wait_ms >= 0, got {max_batch}, {max_pending}, {wait_ms}")
        self.runner, self.format = runner, fmt
        self.input_dtype = np.dtype(str(fmt.input_dtype).replace("torch.", ""))
        self.max_batch, self.wait, self.max_pending = max_batch, wait_ms / 1000.0, max_pending
        self.pending = 0
        self.jobs: queue.SimpleQueue = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.counts = collections.Counter()
        self.recent = collections.deque(maxlen=WINDOW)  # (finished at, latency s): bounded, whatever the traffic
        self.worker = threading.Thread(target=self._work, name="batcher", daemon=True)
        self.worker.start()

    def submit(self, frame: np.ndarray) -> np.ndarray:
        """The graded ``frame`` (``(height, width, 3)`` of the model's input dtype); :class:`Busy` when full."""
        if frame.dtype != self.input_dtype:
            raise ValueError(f"the model takes {self.input_dtype} frames, got {frame.dtype}")
        with self.lock:
            if self.pending >= self.max_pending:
                self.counts["rejected"] += 1
                raise Busy(f"{self.max_pending} frames pending")
            self.pending += 1
        try:
            job = _Job(frame)
            self.jobs.put(job)
            job.done.wait()
            if job.error is not None:
                raise job.error
            return job.result
        finally:
            with self.lock:
                self.pending -= 1

    def stop(self) -> None:
        self.jobs.put(None)
        self.worker.join()

    def _work(self) -> None:
        while True:
            first = self.jobs.get()
            if first is None:
                return
            jobs, deadline, stopping = [first], time.perf_counter() + self.wait, False
            while len(jobs) < self.max_batch and (left := deadline - time.perf_counter()) > 0:
                try:
                    job = self.jobs.get(timeout=left)
                except queue.Empty:
                    break
                if job is None:
                    stopping = True
                    break
                jobs.append(job)
            groups = collections.defaultdict(list)
            for job in jobs:
                groups[job.frame.shape].append(job)
            for group in groups.values():
                self._run(group)
            if stopping:
                return

    def _run(self, jobs: list) -> None:
        try:
            batch = np.stack([job.frame for job in jobs])
            if self.format.layout == "NCHW":
                batch = batch.transpose(0, 3, 1, 2)
            output = self.runner.run(["output"], {"image": np.ascontiguousarray(batch)})[0]
            if self.format.output_layout == "NCHW":
                output = output.transpose(0, 2, 3, 1)
            for job, result in zip(jobs, output):
                job.result = np.ascontiguousarray(result)
        except Exception as error:  # every waiting request gets the error, not a hang
            for job in jobs:
                job.error = error
        finished = time.perf_counter()
        with self.lock:
            self.counts["batches"] += 1
            self.counts["frames"] += len(jobs)
            self.recent.extend((finished, finished - job.started) for job in jobs)
        for job in jobs:
            job.done.set()

    def stats(self) -> dict:
        with self.lock:
            counts, recent, pending = dict(self.counts), list(self.recent), self.pending
        frames, batches = counts.get("frames", 0), counts.get("batches", 0)
        latencies = sorted(latency for _, latency in recent)
        span = recent[-1][0] - recent[0][0] if len(recent) > 1 else 0.0
        return {
            "frames": frames, "batches": batches, "mean_batch": round(frames / batches, 2) if batches else 0.0,
            "rejected": counts.get("rejected", 0), "pending": pending,
            "latency_ms_p50": round(1000 * latencies[len(latencies) // 2], 2) if latencies else None,
            "latency_ms_p99": round(1000 * latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))], 2) if latencies else None,
            "throughput_fps": round((len(recent) - 1) / span, 1) if span > 0 else None,
            "rss_mib": round(resident_mib(), 1),
        }


def decode_image(body: bytes, fmt, max_pixels: int) -> np.ndarray:
    """A PNG or OpenEXR file's bytes as the ``(height, width, 3)`` frame a model of format ``fmt`` takes."""
    if body.startswith(b"\x89PNG\r\n\x1a\n"):
        from PIL import Image

        with Image.open(io.BytesIO(body)) as png:
            if png.width * png.height > max_pixels:
                raise ValueError(f"image of {png.width}x{png.height} pixels, over {max_pixels}")
            if png.mode not in ("RGB", "RGBA"):
                raise ValueError(f"PNG must be 8-bit RGB or RGBA, got mode {png.mode}")
            codes = torch.from_numpy(np.asarray(png.convert("RGB"))).permute(2, 0, 1)
        linear = tg.color.transfer.srgb_to_linear(codes / 255.0)
    elif body.startswith(b"\x76\x2f\x31\x01"):
        with tempfile.NamedTemporaryFile(suffix=".exr") as file:  # the EXR reader reads files, its budget from the header
            file.write(body)
            file.flush()
            linear = tg.io.read_exr(file.name, to_rec709=True, max_pixels=max_pixels)[:3]
    else:
        raise ValueError("an image is a PNG or an OpenEXR file")
    return tg.onnx.model_input(linear[None], fmt._replace(layout="NHWC"))[0].numpy()


def make_server(model, host: str = "127.0.0.1", port: int = 8000, max_batch: int = 8, wait_ms: float = 5.0,
                max_pending: int = 64, max_bytes: int = 64 << 20, device: str = "cpu", threads: Optional[int] = None):
    """The HTTP server (``serve_forever()`` to run it) and its :class:`Batcher`, for the ONNX file ``model``."""
    batcher = Batcher(tg.onnx.session(model, device=device, threads=threads), max_batch, wait_ms, max_pending)
    max_pixels = max_bytes // 3

    class Handler(BaseHTTPRequestHandler):
        disable_nagle_algorithm = True  # the body follows the headers at once, not after the client's delayed ACK (40 ms)

        def _answer(self, status: int, body: bytes, kind: str = "application/octet-stream") -> None:
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def _json(self, status: int, value) -> None:
            self._answer(status, json.dumps(value).encode(), "application/json")

        def do_GET(self):
            if self.path == "/stats":
                self._json(200, batcher.stats())
            elif self.path == "/model":
                fmt = batcher.format
                self._json(200, {"input_dtype": batcher.input_dtype.str, "layout": fmt.layout, "output": fmt.output,
                                 "output_dtype": str(fmt.output_dtype).replace("torch.", ""), "output_layout": fmt.output_layout,
                                 "max_batch": max_batch, "wait_ms": wait_ms, "max_pending": max_pending})
            else:
                self._json(404, {"error": f"no {self.path}: GET /stats or /model, POST /frame or /image"})

        def do_POST(self):
            if self.path not in ("/frame", "/image"):
                self._json(404, {"error": f"no {self.path}: POST /frame or /image"})
                return
            length = int(self.headers.get("Content-Length") or -1)
            if not 0 <= length <= max_bytes:
                self.close_connection = True  # the body is not read
                self._json(413 if length > max_bytes else 411, {"error": f"a body of 0 to {max_bytes} bytes, with its Content-Length"})
                return
            body = self.rfile.read(length)
            try:
                frame = unpack_frame(body) if self.path == "/frame" else decode_image(body, batcher.format, max_pixels)
                self._answer(200, pack_frame(batcher.submit(frame)))
            except Busy as busy:
                self._json(503, {"error": str(busy)})
            except ValueError as error:
                self._json(400, {"error": str(error)})

        def log_message(self, *args):  # a line per request would cost more than a small frame's batch share
            pass

    server = ThreadingHTTPServer((host, port), Handler)
    server.daemon_threads = True
    return server, batcher


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="an ONNX file from tg.onnx.export or torchgrade export")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000, help="0: any free port (printed)")
    parser.add_argument("--max-batch", type=int, default=8, help="frames per batch at most")
    parser.add_argument("--wait-ms", type=float, default=5.0, help="how long the first frame of a batch waits for more")
    parser.add_argument("--max-pending", type=int, default=64, help="frames admitted at once; beyond: 503")
    parser.add_argument("--max-bytes", type=int, default=64 << 20, help="largest request body; beyond: 413")
    parser.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N (onnxruntime-gpu)")
    parser.add_argument("--threads", type=int, help="onnxruntime threads per batch (default: one per core)")
    args = parser.parse_args(argv)
    server, batcher = make_server(args.model, args.host, args.port, args.max_batch, args.wait_ms, args.max_pending,
                                  args.max_bytes, args.device, args.threads)
    fmt = batcher.format
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))  # a stop from a process manager closes the socket too
    print(f"serving {args.model} on http://{server.server_address[0]}:{server.server_address[1]} "
          f"(frames {batcher.input_dtype} {fmt.layout} -> {fmt.output} {fmt.output_layout}; batches of up to "
          f"{args.max_batch} within {args.wait_ms} ms; {args.max_pending} pending at most)", flush=True)
    try:
        server.serve_forever()
    except (KeyboardInterrupt, SystemExit):
        pass
    finally:
        server.server_close()
        batcher.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
