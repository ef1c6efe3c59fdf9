"""The replica of the serving example (``serve.py``): an onnxruntime session of the model, the request handling, and
the batched calls (``@serve.batch``). A module of its own, so that Ray's workers import it (``serve.py`` ships this
folder to them as their working directory).

A request goes through, each step before the next one's cost is paid: its ``Content-Length`` (411, 413); the head of
its body, which says how many pixels it holds (a frame's 16-byte header, a PNG's ``IHDR``, an EXR's headers: 400 for
a malformed, unsupported or over-budget image); the memory it will hold (:mod:`memory`: 413 if it could never fit,
else it waits in line); the rest of its body (:mod:`body`: 408 when it comes slower than the minimum rate); its
decoding, off the event loop; its batch, graded on the replica's one grading thread (in parts that fit the memory kept
for grading), so ``/stats`` and admission keep answering meanwhile. A request whose client left or timed out is
dropped from its batch before the batch (or its part) runs.
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import threading
import time
from dataclasses import asdict, dataclass

import numpy as np
from ray import serve

from torchgrade.base.budget import check_pixels

from body import Body, Refused
from frames import HEADER, frame_header, pack_frame, unpack_frame
from images import EXR_HEAD_BYTES, PNG_HEAD_BYTES, check_kind, decode_image, image_header, sample_body
from limits import Limits
from memory import RETAINED_MIB, Cost, MemoryBudget, OverBudget, peak_growth, peak_mib, reset_peak, resident_mib

__all__ = ["Looks", "Ticket"]

WINDOW = 1000
"""Frames the latency figures of ``/stats`` are taken over (the most recent)."""
PROBE_SIDES = (256, 512)
"""Sides of the square probe frames whose peak memory gives decoding each kind of request, and grading, their costs."""


def _route(request) -> str:
    """The request's path below the application's route prefix (``/frame`` of ``/strict/frame``)."""
    path, root = request.url.path, request.scope.get("root_path", "")
    if root and path.startswith(root):
        path = path[len(root):]
    return path.rstrip("/") or "/"


def _session(model: str, threads: int | None):
    """An onnxruntime session of ``model`` without its memory arena, which keeps a run's peak for good: freed buffers
    go back to the allocator, where later runs and requests reuse them, so the memory budget counts what runs hold."""
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.enable_cpu_mem_arena = False
    if threads is not None:
        options.intra_op_num_threads = threads
    return onnxruntime.InferenceSession(model, options, providers=["CPUExecutionProvider"])


@dataclass
class Ticket:
    """A frame in a batch, and whether anyone still waits for it: not once its request was cancelled (the client left,
    or the proxy answered 408) or its deadline passed."""

    frame: np.ndarray
    deadline: float
    gone: bool = False

    def wanted(self) -> bool:
        return not self.gone and time.monotonic() < self.deadline


class Looks:
    """The replica: an onnxruntime session of the model, the request handling and the batched calls."""

    def __init__(self, model: str, limits: Limits, threads: int | None = None):
        import torchgrade as tg  # in the replica's process

        self.session = _session(model, threads)
        self.format = tg.onnx.read_frame_format(self.session.get_modelmeta().custom_metadata_map)
        required = [port.name for port in self.session.get_inputs()[1:] if not port.type.startswith("optional")]
        if required:
            raise ValueError(f"this server feeds the image alone; the model requires {required}: export it with optional inputs")
        self.input_dtype = np.dtype(str(self.format.input_dtype).replace("torch.", ""))
        self.limits = limits
        self._batched.set_max_batch_size(limits.max_batch)
        self._batched.set_batch_wait_timeout_s(limits.wait_ms / 1000.0)
        self.grader = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="grade")
        self.lock, self.counts, self.running = threading.Lock(), collections.Counter(), 0
        self.recent = collections.deque(maxlen=WINDOW)  # latencies: bounded, whatever the traffic
        self.max_pixels, self.batch_room = limits.max_pixels, 0  # the probes run single frames
        self.output_dtype = np.dtype(str(self.format.output_dtype).replace("torch.", ""))
        self.decoding, self.grading = self._measure()
        self.counts.clear()
        self.idle_mib = resident_mib()
        self.memory, self.batch_room = self._memory_budget()
        reset_peak()

    def _memory_budget(self) -> tuple[MemoryBudget, int]:
        """The memory requests may hold, and the room kept for the batch being graded: each half of the budget less
        what the replica holds idle and what glibc keeps freed. The pixel budget is lowered to the largest raw frame
        that both fit alone."""
        room = (self.limits.memory_mib - self.idle_mib - RETAINED_MIB) * 2**20
        if room <= 0:
            raise ValueError(f"the replica holds {self.idle_mib:.0f} MiB idle and keeps up to {RETAINED_MIB} MiB freed: "
                             f"more than its {self.limits.memory_mib} MiB memory budget")
        held = max(self.decoding.values(), key=lambda cost: cost.per_pixel)
        body = 3 * self.input_dtype.itemsize
        held = Cost(held.fixed, held.per_pixel + 2 * body + 2 * 3 * self.output_dtype.itemsize)
        self.max_pixels = min(self.max_pixels, held.pixels(room / 2), self.grading.pixels(room / 2))
        return MemoryBudget(int(room / 2)), int(room / 2)

    def _measure(self) -> tuple[dict, Cost]:
        """The cost of decoding a request of each kind the model takes and of grading a frame, from the peak memory of
        probe frames decoded and graded here (a first one, not measured, pays their first-use costs)."""
        kinds = ("frame", "png", "exr") if self.format.input_dtype.is_floating_point else ("frame", "png")
        frame_bytes = 3 * self.input_dtype.itemsize
        decoding = {}
        for kind in kinds:
            bodies = [sample_body(kind, side, self.format) for side in (PROBE_SIDES[0], *PROBE_SIDES)]
            self._decode(kind, bodies[0])
            peaks = [(side * side, peak_growth(lambda kind=kind, body=body: self._decode(kind, body)))
                     for side, body in zip(PROBE_SIDES, bodies[1:])]
            decoding[kind] = Cost.through(*peaks, floor=0 if kind == "frame" else frame_bytes)
        frames = [self._decode("frame", sample_body("frame", side, self.format)) for side in (PROBE_SIDES[0], *PROBE_SIDES)]
        self._grade_now(frames[0])
        peaks = [(side * side, peak_growth(lambda frame=frame: self._grade_now(frame)))
                 for side, frame in zip(PROBE_SIDES, frames[1:])]
        return decoding, Cost.through(*peaks, floor=frame_bytes + 3 * self.output_dtype.itemsize)

    def _grade_now(self, frame: np.ndarray) -> bytes:
        return pack_frame(self._run([Ticket(frame, float("inf"))])[0])

    def held(self, kind: str, pixels: int, body: int) -> int:
        """Bytes a request holds from its header until it is answered: its body twice (the bytes, and a decoder's
        copy), its decoding's peak, its answer twice (the graded frame and its packed bytes)."""
        return 2 * body + self.decoding[kind].bytes(pixels) + 2 * 3 * self.output_dtype.itemsize * pixels

    def _decode(self, kind: str, body) -> np.ndarray:
        if kind == "frame":
            return unpack_frame(body, self.max_pixels)
        return decode_image(body, self.format, self.max_pixels)

    async def __call__(self, request):
        from starlette.requests import ClientDisconnect
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
            answer = await self._graded(request, path)
        except Refused as refused:
            return self._refuse(refused.status, str(refused))
        except OverBudget as error:
            return self._refuse(413, f"this request cannot be served here: {error}")
        except ValueError as error:  # a malformed frame or image
            return self._refuse(400, str(error))
        except (asyncio.CancelledError, ClientDisconnect) as gone:
            self._count("left")
            if isinstance(gone, asyncio.CancelledError):
                raise
            return Response(status_code=499)  # nginx's code for a request its client closed: nobody reads it
        with self.lock:
            self.recent.append(time.perf_counter() - started)
        return Response(answer, media_type="application/octet-stream")

    def _count(self, name: str, amount: int = 1) -> None:
        with self.lock:
            self.counts[name] += amount

    def _refuse(self, status: int, reason: str):
        from starlette.responses import JSONResponse

        self._count(f"refused_{status}")
        return JSONResponse({"error": reason[:2000]}, status_code=status)

    def _length(self, request) -> int:
        """The body's declared length, refused before anything is read where missing or over the budget."""
        declared = request.headers.get("content-length")
        if declared is None or not declared.isdigit():
            raise Refused(411, f"a body needs its Content-Length, at most {self.limits.max_bytes} bytes")
        if int(declared) > self.limits.max_bytes:
            raise Refused(413, f"a body of {declared} bytes is more than the {self.limits.max_bytes} this server reads")
        return int(declared)

    async def _graded(self, request, path: str) -> bytes:
        """The graded frame of a ``/frame`` or ``/image`` request, packed; each limit checked before its cost is paid."""
        deadline = time.monotonic() + self.limits.timeout_s
        body = Body(request, self._length(request), self.limits.min_body_rate, self.limits.body_grace_s, deadline)
        kind, pixels = await (self._frame_head(body) if path == "/frame" else self._image_head(body))
        waited = time.monotonic()
        async with self.memory.reserved(self.held(kind, pixels, body.length)):
            body.pause(time.monotonic() - waited)
            data = await body.whole()
            frame = self._decode(kind, data) if kind == "frame" else await asyncio.to_thread(self._decode, kind, data)
            ticket = Ticket(frame, deadline)
            try:
                graded = await self._batched(ticket)
            except asyncio.CancelledError:
                ticket.gone = True
                raise
            if graded is None:
                raise Refused(408, f"the request was not graded within {self.limits.timeout_s} s")
            return await asyncio.to_thread(pack_frame, graded)

    async def _frame_head(self, body: Body) -> tuple[str, int]:
        """A raw frame's kind and pixels from its 16-byte header: its dtype and its length checked against the model
        and the ``Content-Length`` before the samples are read."""
        height, width, dtype, expected = frame_header(await body.head(HEADER.size), self.max_pixels)
        if dtype != self.input_dtype:
            raise Refused(400, f"the model takes {self.input_dtype} frames, got {dtype}")
        if body.length != expected:
            raise Refused(400, f"a {height}x{width} {dtype} frame is {expected} bytes, its Content-Length says {body.length}")
        return "frame", height * width

    async def _image_head(self, body: Body) -> tuple[str, int]:
        """An image file's kind and pixels from its header, read a few KiB at a time (an EXR's headers run on)."""
        size = PNG_HEAD_BYTES
        while (found := image_header(head := await body.head(size), body.ended or len(head) >= EXR_HEAD_BYTES)) is None:
            size = min(max(4 * size, 4096), EXR_HEAD_BYTES)
        kind, height, width = found
        check_pixels(height, width, "an image", self.max_pixels)
        check_kind(kind, self.format)
        return kind, height * width

    @serve.batch(max_batch_size=8, batch_wait_timeout_s=0.005)
    async def _batched(self, tickets: list) -> list:
        """Frames gathered by Ray Serve (up to ``max_batch`` within ``wait_ms``, set in ``__init__``), graded on the
        grading thread."""
        return await asyncio.get_running_loop().run_in_executor(self.grader, self._run, tickets)

    def _run(self, tickets: list) -> list:
        """The model on the frames still wanted, grouped by size, each group one batch (or parts of one, see
        :meth:`_split`); in the order given, ``None`` for a frame no one waits for."""
        groups = collections.defaultdict(list)
        for index, ticket in enumerate(tickets):
            groups[ticket.frame.shape].append(index)
        results = [None] * len(tickets)
        for same_size in groups.values():
            for indices in self._split(tickets, same_size):
                self._grade(tickets, indices, results)
        return results

    def _split(self, tickets: list, same_size: list):
        """The frames of a group still wanted (asked again before each part), in parts whose grading fits the room kept
        for the running batch."""
        pixels = tickets[same_size[0]].frame.shape[0] * tickets[same_size[0]].frame.shape[1]
        per_part = max(1, self.grading.pixels(self.batch_room) // pixels) if self.batch_room else len(same_size)
        while same_size:
            part, same_size = same_size[:per_part], same_size[per_part:]
            indices = [index for index in part if tickets[index].wanted()]
            self._count("skipped", len(part) - len(indices))
            if indices:
                yield indices

    def _grade(self, tickets: list, indices: list, results: list) -> None:
        """The model on the frames ``indices`` of ``tickets`` as one batch, their results into ``results``."""
        batch = np.stack([tickets[index].frame for index in indices])
        if self.format.layout == "NCHW":
            batch = batch.transpose(0, 3, 1, 2)
        self.running = len(indices)
        try:
            output = self.session.run(["output"], {"image": np.ascontiguousarray(batch)})[0]
        finally:
            self.running = 0
        del batch
        if self.format.output_layout == "NCHW":
            output = output.transpose(0, 2, 3, 1)
        for index, result in zip(indices, output):
            results[index] = np.ascontiguousarray(result)
        self._count("batches")
        self._count("frames", len(indices))

    def model(self) -> dict:
        fmt = self.format
        costs = {"grading": self.grading.mib(), **{f"decoding_{kind}": cost.mib() for kind, cost in self.decoding.items()}}
        return {"input_dtype": self.input_dtype.str, "layout": fmt.layout, "output": fmt.output,
                "output_dtype": str(fmt.output_dtype).replace("torch.", ""), "output_layout": fmt.output_layout,
                **asdict(self.limits), "max_pixels": self.max_pixels, "idle_mib": round(self.idle_mib, 1), "costs": costs,
                "requests_room_mib": round(self.memory.capacity / 2**20, 1), "batch_room_mib": round(self.batch_room / 2**20, 1)}

    def stats(self) -> dict:
        with self.lock:
            counts, latencies = dict(self.counts), sorted(self.recent)
        frames, batches = counts.pop("frames", 0), counts.pop("batches", 0)
        gone = {name: counts.pop(name, 0) for name in ("left", "skipped")}
        return {"frames": frames, "batches": batches, "mean_batch": round(frames / batches, 2) if batches else 0.0,
                "refused": counts, **gone, "running": self.running,
                "latency_ms_p50": round(1000 * latencies[len(latencies) // 2], 2) if latencies else None,
                "latency_ms_p99": round(1000 * latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))], 2) if latencies else None,
                "memory": {"held_mib": round(self.memory.held / 2**20, 1), "held_peak_mib": round(self.memory.peak / 2**20, 1),
                           "waiting": self.memory.waiting, "waited": self.memory.waited},
                "rss_mib": round(resident_mib(), 1), "peak_rss_mib": round(peak_mib(), 1)}
