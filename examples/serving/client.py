"""Load for the serving example: frames or image files sent from many threads at once, optionally while other
connections trickle their bodies a byte at a time; then the client's and the server's figures.

    python examples/serving/client.py http://127.0.0.1:8000 [--frames 200] [--concurrency 8] [--size 1080x1920]
                                      [--image FILE ...] [--slow 24] [--json FILE]

``--image`` sends those PNG or EXR files (in turn) to ``/image`` instead of random frames to ``/frame``; ``--slow N``
keeps N connections trickling a frame to ``/frame`` at a byte every 0.1 s, each reconnecting when it is answered,
while the frames are sent: the server should answer them 408 and the others as usual. ``--json`` writes the figures.
"""

from __future__ import annotations

import argparse
import json
import select
import socket
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from frames import pack_frame  # noqa: E402

__all__ = ["get_json", "percentile_ms", "post", "random_frame", "read_answer", "send_all", "trickle"]


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


def read_answer(connection: socket.socket, silence_s: float = 5.0) -> bytes:
    """What the server sends on ``connection`` until it closes it (or stays silent for ``silence_s`` seconds)."""
    connection.settimeout(silence_s)
    chunks = []
    try:
        while chunk := connection.recv(65536):
            chunks.append(chunk)
    except OSError:  # silent, or reset once it had answered
        pass
    return b"".join(chunks)


def _trickle_once(address: tuple, path: str, body: bytes, stop: threading.Event, interval: float) -> bytes:
    """One connection sending ``body`` a byte every ``interval`` seconds until it is answered (or ``stop``)."""
    with socket.create_connection(address, timeout=10.0) as connection:
        head = b"POST %s HTTP/1.1\r\nHost: %s\r\nContent-Length: %d\r\n\r\n"
        connection.sendall(head % (path.encode(), address[0].encode(), len(body)))
        for at in range(len(body)):
            if stop.is_set() or select.select([connection], [], [], interval)[0]:
                break
            try:
                connection.sendall(body[at:at + 1])
            except OSError:
                break
        return read_answer(connection) if not stop.is_set() else b""


def trickle(url: str, path: str, body: bytes, stop: threading.Event, interval: float = 0.1) -> list:
    """Send ``body`` to ``url + path`` a byte every ``interval`` seconds on a new connection each time the server
    answers, until ``stop`` is set: each answer's bytes (status line, headers and body)."""
    parts = urlsplit(url)
    answers = []
    while not stop.is_set():
        answer = _trickle_once((parts.hostname, parts.port), path, body, stop, interval)
        if answer:
            answers.append(answer)
    return answers


def send_all(url: str, bodies: list, concurrency: int, path: str = "/frame") -> tuple:
    """``(statuses, latencies in s)`` of posting every body in ``bodies`` from ``concurrency`` threads, each taking the
    next body not yet sent."""
    statuses, latencies, lock, pending = [], [], threading.Lock(), list(reversed(bodies))

    def send() -> None:
        while True:
            with lock:
                if not pending:
                    return
                body = pending.pop()
            start = time.perf_counter()
            status, _ = post(url + path, body)
            with lock:
                latencies.append(time.perf_counter() - start)
                statuses.append(status)

    threads = [threading.Thread(target=send) for _ in range(concurrency)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return statuses, latencies


def percentile_ms(latencies: list, share: float) -> float:
    """The ``share`` quantile of ``latencies`` (seconds) in ms, the nearest rank below."""
    ordered = sorted(latencies)
    return round(1000 * ordered[int(share * (len(ordered) - 1))], 1)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url", help="the server, http://host:port")
    parser.add_argument("--frames", type=int, default=200, help="requests to send")
    parser.add_argument("--concurrency", type=int, default=8)
    parser.add_argument("--size", default="1080x1920", help="HEIGHTxWIDTH of the random frames")
    parser.add_argument("--image", action="append", type=Path, help="a PNG or EXR file to send (repeat for more)")
    parser.add_argument("--slow", type=int, default=0, help="connections trickling a frame meanwhile")
    parser.add_argument("--json", type=Path, help="write the figures to this file")
    args = parser.parse_args(argv)
    dtype = get_json(args.url + "/model")["input_dtype"]
    if args.image:
        files = [path.read_bytes() for path in args.image]
        bodies, path, what = [files[index % len(files)] for index in range(args.frames)], "/image", f"{len(files)} files"
    else:
        height, width = (int(side) for side in args.size.split("x"))
        bodies, path, what = [pack_frame(random_frame(height, width, dtype))] * args.frames, "/frame", f"frames {args.size}"
    stop, slow_answers, slow_body = threading.Event(), [], pack_frame(random_frame(64, 64, dtype))
    tricklers = [threading.Thread(target=lambda: slow_answers.extend(trickle(args.url, "/frame", slow_body, stop)))
                 for _ in range(args.slow)]
    for trickler in tricklers:
        trickler.start()
    start = time.perf_counter()
    statuses, latencies = send_all(args.url, bodies, args.concurrency, path)
    elapsed = time.perf_counter() - start
    stop.set()
    for trickler in tricklers:
        trickler.join()
    figures = {"requests": args.frames, "sent": what, "concurrency": args.concurrency, "seconds": round(elapsed, 2),
               "answered_per_s": round(statuses.count(200) / elapsed, 2), "latency_ms_p50": percentile_ms(latencies, 0.5),
               "latency_ms_p99": percentile_ms(latencies, 0.99), "latency_ms_max": percentile_ms(latencies, 1.0),
               "statuses": {str(status): statuses.count(status) for status in sorted(set(statuses))},
               "slow_connections": args.slow, "slow_answers": {}, "server": get_json(args.url + "/stats")}
    for answer in slow_answers:
        status = answer.split(b" ", 2)[1].decode() if answer.startswith(b"HTTP/") else "other"
        figures["slow_answers"][status] = figures["slow_answers"].get(status, 0) + 1
    print(json.dumps(figures))
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
