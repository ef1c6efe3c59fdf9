"""Serving a torchgrade ONNX model on Ray Serve: its HTTP proxy, a replica running onnxruntime, batching by
``@serve.batch``.

    python examples/serving/serve.py look.onnx [--port 8000] [--max-batch 8] [--wait-ms 5] [--max-ongoing 16]
                                               [--max-queued 64] [--max-bytes 67108864] [--timeout 30]

Endpoints:

* ``POST /frame``: a raw frame (``frames.py``); the answer is the graded frame, same format.
* ``POST /image``: the bytes of a PNG (8-bit RGB/RGBA, sRGB) or OpenEXR file (linear); the answer is the graded frame.
  The file is decoded to linear light and given to the model as its input takes it (integer inputs: sRGB codes).
* ``GET /stats``: JSON: frames, batches, mean batch size, refused requests by status, latency p50/p99 ms over the
  last 1000 frames, the replica's resident memory (MiB).
* ``GET /model``: JSON: the model's frame format and the server's settings.

**Bounded, before a body is read.** Ray Serve admits at most ``--max-ongoing`` requests to the replica and queues at
most ``--max-queued`` more; beyond that its proxy answers 503 without reading the request. An admitted request's
``Content-Length`` is checked before its body is read (413 past ``--max-bytes``, 411 without one), and the body is
read in chunks that may not pass it either; a frame's header (its pixels, against the pixel budget) is checked
before its samples are read, an image file's before it is decoded (:func:`frames.decode_image`). A request not
answered in ``--timeout`` seconds is answered 408 by the proxy. Malformed requests get 400 with the reason.

**Batching.** ``@serve.batch`` gathers up to ``--max-batch`` frames within ``--wait-ms`` of the first; they are grouped
by size and each group runs as one batch. On a CPU a frame already runs on every core (see ``docs/onnx.md``).

A look with eye adaptation serves stills: the model's ``adapted`` and ``dt`` inputs are left to their defaults
(instant adaptation); every input but the image must have a default (``tg.onnx.export``'s ``optional_inputs=True``).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from frames import HEADER  # noqa: E402

def deployment(model: str, max_batch: int = 8, wait_ms: float = 5.0, max_ongoing: int = 16, max_queued: int = 64,
               max_bytes: int = 64 << 20, max_pixels: int | None = None, threads: int | None = None):
    """The Ray Serve application of ``model`` (an ONNX file): ``serve.run(deployment(...))`` serves it."""
    from ray import serve

    from torchgrade.base.budget import MAX_PIXELS

    if max_batch < 1 or max_ongoing < 1 or max_queued < 0 or wait_ms < 0 or max_bytes < HEADER.size:
        raise ValueError(f"max_batch and max_ongoing must be >= 1, max_queued and wait_ms >= 0 and max_bytes >= "
                         f"{HEADER.size}, got {max_batch}, {max_ongoing}, {max_queued}, {wait_ms}, {max_bytes}")
    from replica import Looks

    max_pixels = max_pixels or min(MAX_PIXELS, max_bytes // 3)
    settings = {"max_batch": max_batch, "wait_ms": wait_ms, "max_ongoing": max_ongoing, "max_queued": max_queued}
    app = serve.deployment(Looks, name="torchgrade", max_ongoing_requests=max_ongoing, max_queued_requests=max_queued,
                           ray_actor_options={"num_cpus": 0})
    return app.bind(str(Path(model).resolve()), max_bytes, max_pixels, threads, settings)


def start_proxy(host: str = "127.0.0.1", port: int = 8000, timeout_s: float = 30.0) -> str:
    """Start Ray (if it is not running) and Serve's HTTP proxy on ``host:port``, answering 408 to a request not done in
    ``timeout_s`` seconds and closing idle connections after 5; its URL."""
    import ray
    from ray import serve

    if not ray.is_initialized():  # the replica imports replica.py and frames.py from this folder
        ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False,
                 runtime_env={"working_dir": str(HERE)})
    serve.start(http_options={"host": host, "port": port, "request_timeout_s": timeout_s, "keep_alive_timeout_s": 5})
    return f"http://{host}:{port}"


def deploy(model: str, name: str = "torchgrade", route_prefix: str = "/", **settings) -> None:
    """Serve ``model`` as the application ``name`` at ``route_prefix`` (:func:`deployment`'s ``settings``)."""
    from ray import serve

    serve.run(deployment(model, **settings), name=name, route_prefix=route_prefix, blocking=False)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="an ONNX file from tg.onnx.export or torchgrade export")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument("--max-batch", type=int, default=8, help="frames per batch at most")
    parser.add_argument("--wait-ms", type=float, default=5.0, help="how long the first frame of a batch waits for more")
    parser.add_argument("--max-ongoing", type=int, default=16, help="requests the replica handles at once")
    parser.add_argument("--max-queued", type=int, default=64, help="requests queued beyond those; then 503")
    parser.add_argument("--max-bytes", type=int, default=64 << 20, help="largest request body; beyond: 413")
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds a request may take; then 408")
    parser.add_argument("--threads", type=int, help="onnxruntime threads per batch (default: one per core)")
    args = parser.parse_args(argv)
    url = start_proxy(args.host, args.port, args.timeout)
    deploy(args.model, max_batch=args.max_batch, wait_ms=args.wait_ms, max_ongoing=args.max_ongoing,
           max_queued=args.max_queued, max_bytes=args.max_bytes, threads=args.threads)
    print(f"serving {args.model} on {url} (Ray Serve; batches of up to {args.max_batch} within {args.wait_ms} ms; "
          f"{args.max_ongoing} requests at once, {args.max_queued} queued; bodies up to {args.max_bytes} bytes)", flush=True)
    stopped = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stopped.set())
    signal.signal(signal.SIGINT, lambda *_: stopped.set())
    stopped.wait()
    from ray import serve

    serve.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
