"""Serving a torchgrade ONNX model on Ray Serve: its HTTP proxy, a replica running onnxruntime, batching by
``@serve.batch``.

    python examples/serving/serve.py look.onnx [--port 8000] [--max-batch 8] [--wait-ms 5] [--max-ongoing 16]
                                               [--max-queued 64] [--max-bytes 67108864] [--timeout 30]
                                               [--memory-mib 4096] [--min-body-rate 131072] [--body-grace 1]

Endpoints:

* ``POST /frame``: a raw frame (``frames.py``); the answer is the graded frame, same format.
* ``POST /image``: the bytes of a PNG (8-bit RGB/RGBA, sRGB) or OpenEXR file (linear; for a model with a float input);
  the answer is the graded frame. The file is decoded to what the model's input takes (``images.py``).
* ``GET /stats``: JSON: frames, batches, mean batch size, refused requests by status, requests whose clients left and
  frames not graded for it, latency p50/p99 ms over the last 1000 frames, the memory requests hold and wait for, the
  replica's resident memory and its peak (MiB).
* ``GET /model``: JSON: the model's frame format, the server's limits and each kind of request's measured cost.

**Bounded, before each cost is paid** (``limits.py`` states every default and why). Ray Serve admits at most
``--max-ongoing`` requests to the replica and queues at most ``--max-queued`` more; beyond that its proxy answers 503
without reading the request. An admitted request's ``Content-Length`` is checked before its body is read (413 past
``--max-bytes``, 411 without one); its body must keep up with ``--min-body-rate`` bytes a second after
``--body-grace`` seconds, and with the pace that ends it before ``--timeout`` (408, and its slot goes to the next
request: ``body.py``); the pixels its header declares are checked against the pixel budget, and its whole cost
(body, decoding, its share of a batch, measured when the replica starts) waits until it fits the replica's
``--memory-mib`` (``memory.py``). A request not answered in
``--timeout`` seconds is answered 408 by the proxy, and its frame is not graded. Malformed requests get 400 with a
short reason.

**Batching.** ``@serve.batch`` gathers up to ``--max-batch`` frames within ``--wait-ms`` of the first; they are grouped
by size and each group runs as one batch, on a thread of its own so that the replica keeps answering meanwhile. On a
CPU a frame already runs on every core (see ``docs/onnx.md``).

A look with eye adaptation serves stills: the model's ``adapted`` and ``dt`` inputs are left to their defaults
(instant adaptation); every input but the image must have a default (``tg.onnx.export``'s ``optional_inputs=True``).
"""

from __future__ import annotations

import argparse
import dataclasses
import errno
import signal
import socket
import sys
import threading
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from limits import Limits  # noqa: E402


def deployment(model: str, limits: Limits = Limits(), threads: int | None = None):
    """The Ray Serve application of ``model`` (an ONNX file): ``serve.run(deployment(...))`` serves it."""
    from ray import serve

    from replica import Looks

    app = serve.deployment(Looks, name="torchgrade", max_ongoing_requests=limits.max_ongoing,
                           max_queued_requests=limits.max_queued, ray_actor_options={"num_cpus": 0})
    return app.bind(str(Path(model).resolve()), limits, threads)


def check_port_free(host: str, port: int) -> None:
    """``OSError`` saying so where ``host:port`` cannot be bound, as Serve's proxy binds it (whose own failure ends in
    an ``ActorDiedError`` that does not say why)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        try:
            probe.bind((host, port))
        except OSError as error:
            reason = "the port is in use" if error.errno == errno.EADDRINUSE else error.strerror
            raise OSError(f"cannot serve on {host}:{port}: {reason} (choose another with --port)") from None


def start_proxy(host: str = "127.0.0.1", port: int = 8000, timeout_s: float = Limits.timeout_s) -> str:
    """Start Ray (if it is not running) and Serve's HTTP proxy on ``host:port``, answering 408 to a request not done in
    ``timeout_s`` seconds and closing idle connections after 5; its URL. ``OSError`` where the port is taken."""
    check_port_free(host, port)
    import ray
    from ray import serve

    if not ray.is_initialized():  # the replica imports this folder's modules; one malloc arena: see memory.py
        ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False,
                 runtime_env={"working_dir": str(HERE), "env_vars": {"MALLOC_ARENA_MAX": "1"}})
    serve.start(http_options={"host": host, "port": port, "request_timeout_s": timeout_s, "keep_alive_timeout_s": 5})
    return f"http://{host}:{port}"


def deploy(model: str, name: str = "torchgrade", route_prefix: str = "/", threads: int | None = None, **limits) -> None:
    """Serve ``model`` as the application ``name`` at ``route_prefix``, with :class:`Limits` ``limits``."""
    from ray import serve

    serve.run(deployment(model, Limits(**limits), threads), name=name, route_prefix=route_prefix, blocking=False)


FLAGS = {"max_batch": "frames per batch at most", "wait_ms": "how long the first frame of a batch waits for more",
         "max_ongoing": "requests the replica handles at once", "max_queued": "requests queued beyond those; then 503",
         "max_bytes": "largest request body; beyond: 413", "timeout_s": "seconds a request may take; then 408",
         "memory_mib": "the replica's memory budget: requests wait until theirs fits",
         "min_body_rate": "bytes a second a body must keep up with; slower: 408",
         "body_grace_s": "seconds before the body rate is enforced"}
"""serve.py's flags: a field of :class:`Limits` each (``--timeout`` and ``--body-grace`` drop the ``_s``)."""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="an ONNX file from tg.onnx.export or torchgrade export")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000)
    for field in dataclasses.fields(Limits):
        if field.name in FLAGS:
            flag = "--" + field.name.removesuffix("_s").replace("_", "-")
            parser.add_argument(flag, dest=field.name, type=type(field.default), default=field.default,
                                help=f"{FLAGS[field.name]} (default {field.default})")
    parser.add_argument("--threads", type=int, help="onnxruntime threads per batch (default: one per core)")
    args = parser.parse_args(argv)
    limits = Limits(**{name: getattr(args, name) for name in FLAGS})
    try:
        url = start_proxy(args.host, args.port, limits.timeout_s)
    except OSError as error:
        print(f"serve.py: {error}", file=sys.stderr)
        return 1
    deploy(args.model, threads=args.threads, **dataclasses.asdict(limits))
    print(f"serving {args.model} on {url} (Ray Serve; batches of up to {limits.max_batch} within {limits.wait_ms} ms; "
          f"{limits.max_ongoing} requests at once, {limits.max_queued} queued; bodies up to {limits.max_bytes} bytes at "
          f"{limits.min_body_rate:.0f} bytes/s or faster; {limits.memory_mib} MiB for the replica)", flush=True)
    stopped = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stopped.set())
    signal.signal(signal.SIGINT, lambda *_: stopped.set())
    stopped.wait()
    from ray import serve

    serve.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
