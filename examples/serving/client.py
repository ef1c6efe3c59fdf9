"""Load for the serving example: frames sent from many threads at once, then the client's and the server's figures.

    python examples/serving/client.py http://127.0.0.1:8000 [--frames 200] [--concurrency 8] [--size 1080x1920]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from frames import pack_frame  # noqa: E402


def post(url: str, body: bytes, timeout: float = 60.0) -> tuple:
    """``(HTTP status, answer bytes)`` of a POST of ``body`` to ``url``."""
    request = urllib.request.Request(url, data=body, method="POST", headers={"Content-Type": "application/octet-stream"})
    try:
        with urllib.request.urlopen(request, timeout=timeout) as answer:
            return answer.status, answer.read()
    except urllib.error.HTTPError as error:
        return error.code, error.read()


def get_json(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=10.0) as answer:
        return json.loads(answer.read())


def random_frame(height: int, width: int, dtype: str, seed: int = 0) -> np.ndarray:
    """A ``(height, width, 3)`` frame of ``dtype``: codes over the dtype's range, floats in [0, 4)."""
    generator = np.random.default_rng(seed)
    dtype = np.dtype(dtype)
    if dtype.kind == "u":
        return generator.integers(0, np.iinfo(dtype).max, (height, width, 3), endpoint=True).astype(dtype)
    return (generator.random((height, width, 3)) * 4.0).astype(dtype)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url", help="the server, http://host:port")
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--concurrency", type=int, default=8)
    parser.add_argument("--size", default="1080x1920", help="HEIGHTxWIDTH")
    args = parser.parse_args(argv)
    height, width = (int(side) for side in args.size.split("x"))
    body = pack_frame(random_frame(height, width, get_json(args.url + "/model")["input_dtype"]))
    latencies, statuses, lock = [], [], threading.Lock()
    per_thread = [args.frames // args.concurrency + (i < args.frames % args.concurrency) for i in range(args.concurrency)]

    def send(count: int) -> None:
        for _ in range(count):
            start = time.perf_counter()
            status, _ = post(args.url + "/frame", body)
            with lock:
                latencies.append(time.perf_counter() - start)
                statuses.append(status)

    threads = [threading.Thread(target=send, args=(count,)) for count in per_thread]
    start = time.perf_counter()
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    elapsed = time.perf_counter() - start
    latencies.sort()
    print(f"{args.frames} frames {height}x{width} from {args.concurrency} threads in {elapsed:.2f} s: "
          f"{statuses.count(200) / elapsed:.1f} frames/s answered, latency p50 {1000 * statistics.median(latencies):.1f} ms, "
          f"p99 {1000 * latencies[int(0.99 * (len(latencies) - 1))]:.1f} ms; statuses {dict(sorted({s: statuses.count(s) for s in statuses}.items()))}")
    print("server:", json.dumps(get_json(args.url + "/stats")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
