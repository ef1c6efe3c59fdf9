"""The replica of the serving example (``serve.py``): an onnxruntime session of the model, the request handling, and
the batched calls (``@serve.batch``). A module of its own, so that Ray's workers import it (``serve.py`` ships this
folder to them as their working directory).
"""

from __future__ import annotations

import collections
import os
import resource
import sys
import threading
import time

import numpy as np
from ray import serve

from frames import HEADER, decode_image, frame_header, pack_frame

WINDOW = 1000
"""Frames the latency figures of ``/stats`` are taken over (the most recent)."""


def resident_mib() -> float:
    """This process's resident memory in MiB (``/proc/self/statm``; elsewhere its peak, from ``getrusage``)."""
    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / 2**20 if sys.platform == "darwin" else peak / 1024


def _route(request) -> str:
    """The request's path below the application's route prefix (``/frame`` of ``/strict/frame``)."""
    path, root = request.url.path, request.scope.get("root_path", "")
    if root and path.startswith(root):
        path = path[len(root):]
    return path.rstrip("/") or "/"


class Refused(Exception):
    """A request answered with a 4xx status and a reason."""

    def __init__(self, status: int, reason: str):
        super().__init__(reason)
        self.status = status


class Looks:
    """The replica: an onnxruntime session of the model, the request handling and the batched calls."""

    def __init__(self, model: str, max_bytes: int, max_pixels: int, threads: int | None, settings: dict):
        import torchgrade as tg  # in the replica's process

        self.session = tg.onnx.session(model, threads=threads)
        self.format = tg.onnx.read_frame_format(self.session.get_modelmeta().custom_metadata_map)
        required = [port.name for port in self.session.get_inputs()[1:] if not port.type.startswith("optional")]
        if required:
            raise ValueError(f"this server feeds the image alone; the model requires {required}: export it with optional inputs")
        self.input_dtype = np.dtype(str(self.format.input_dtype).replace("torch.", ""))
        self.max_bytes, self.max_pixels, self.settings = max_bytes, max_pixels, settings
        self._batched.set_max_batch_size(settings["max_batch"])
        self._batched.set_batch_wait_timeout_s(settings["wait_ms"] / 1000.0)
        self.lock = threading.Lock()
        self.counts = collections.Counter()
        self.recent = collections.deque(maxlen=WINDOW)  # latencies: bounded, whatever the traffic

    async def __call__(self, request):
        from starlette.responses import JSONResponse, Response

        path, method = _route(request), request.method
        started = time.perf_counter()
        try:
            if method == "GET" and path == "/stats":
                return JSONResponse(self.stats())
            if method == "GET" and path == "/model":
                return JSONResponse(self.model())
            if method != "POST" or path not in ("/frame", "/image"):
                raise Refused(404, f"no {method} {path}: GET /stats or /model, POST /frame or /image")
            frame = await self._frame(request) if path == "/frame" else decode_image(await self._body(request), self.format,
                                                                                     self.max_pixels)
            if frame.dtype != self.input_dtype:
                raise Refused(400, f"the model takes {self.input_dtype} frames, got {frame.dtype}")
            graded = await self.graded(frame)
        except Refused as refused:
            return self._refuse(refused.status, str(refused))
        except ValueError as error:  # a malformed frame or image
            return self._refuse(400, str(error))
        with self.lock:
            self.recent.append(time.perf_counter() - started)
        return Response(pack_frame(graded), media_type="application/octet-stream")

    def _refuse(self, status: int, reason: str):
        from starlette.responses import JSONResponse

        with self.lock:
            self.counts[f"refused_{status}"] += 1
        return JSONResponse({"error": reason[:2000]}, status_code=status)

    def _length(self, request) -> int:
        """The body's declared length, refused before anything is read where missing or over the budget."""
        declared = request.headers.get("content-length")
        if declared is None or not declared.isdigit():
            raise Refused(411, f"a body needs its Content-Length, at most {self.max_bytes} bytes")
        if int(declared) > self.max_bytes:
            raise Refused(413, f"a body of {declared} bytes is more than the {self.max_bytes} this server reads")
        return int(declared)

    async def _body(self, request, expected: int | None = None) -> bytes:
        """The body, read a chunk at a time, never past its declared length (or ``expected``, a frame's)."""
        limit = min(self._length(request), expected if expected is not None else self.max_bytes)
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > limit:
                raise Refused(413, f"the body is longer than the {limit} bytes it may hold")
            chunks.append(chunk)
        return b"".join(chunks)

    async def _frame(self, request) -> np.ndarray:
        """A raw frame: its header first, the pixels it declares checked against the budget before the samples are
        read."""
        self._length(request)
        stream = request.stream()
        head = b""
        async for chunk in stream:
            head += chunk
            if len(head) >= HEADER.size:
                break
        height, width, dtype, expected = frame_header(head[: HEADER.size], self.max_pixels)
        if int(request.headers["content-length"]) != expected:
            raise Refused(400, f"a {height}x{width} {dtype} frame is {expected} bytes, its Content-Length says "
                               f"{request.headers['content-length']}")
        chunks, size = [head], len(head)
        async for chunk in stream:
            size += len(chunk)
            if size > expected:
                raise Refused(413, f"the body is longer than the {expected} bytes its header declares")
            chunks.append(chunk)
        body = b"".join(chunks)
        if len(body) != expected:
            raise Refused(400, f"a {height}x{width} {dtype} frame is {expected} bytes, got {len(body)}")
        return np.frombuffer(body, dtype, offset=HEADER.size).reshape(height, width, 3)

    async def graded(self, frame: np.ndarray) -> np.ndarray:
        return await self._batched(frame)

    @serve.batch(max_batch_size=8, batch_wait_timeout_s=0.005)
    async def _batched(self, frames: list) -> list:
        """Frames gathered by Ray Serve (up to ``max_batch`` within ``wait_ms``, set in ``__init__``), run together."""
        return self._run(frames)

    def _run(self, frames: list) -> list:
        """The model on ``frames``, grouped by size, each group one batch; in the order given."""
        groups = collections.defaultdict(list)
        for index, frame in enumerate(frames):
            groups[frame.shape].append(index)
        results = [None] * len(frames)
        for indices in groups.values():
            batch = np.stack([frames[index] for index in indices])
            if self.format.layout == "NCHW":
                batch = batch.transpose(0, 3, 1, 2)
            output = self.session.run(["output"], {"image": np.ascontiguousarray(batch)})[0]
            if self.format.output_layout == "NCHW":
                output = output.transpose(0, 2, 3, 1)
            for index, result in zip(indices, output):
                results[index] = np.ascontiguousarray(result)
        with self.lock:
            self.counts["batches"] += len(groups)
            self.counts["frames"] += len(frames)
        return results

    def model(self) -> dict:
        fmt = self.format
        return {"input_dtype": self.input_dtype.str, "layout": fmt.layout, "output": fmt.output,
                "output_dtype": str(fmt.output_dtype).replace("torch.", ""), "output_layout": fmt.output_layout,
                "max_bytes": self.max_bytes, "max_pixels": self.max_pixels, **self.settings}

    def stats(self) -> dict:
        with self.lock:
            counts, latencies = dict(self.counts), sorted(self.recent)
        frames, batches = counts.pop("frames", 0), counts.pop("batches", 0)
        return {"frames": frames, "batches": batches, "mean_batch": round(frames / batches, 2) if batches else 0.0,
                "refused": counts,
                "latency_ms_p50": round(1000 * latencies[len(latencies) // 2], 2) if latencies else None,
                "latency_ms_p99": round(1000 * latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))], 2) if latencies else None,
                "rss_mib": round(resident_mib(), 1)}
