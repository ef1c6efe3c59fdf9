"""examples/serving on Ray Serve, on the loopback address: frames and image files sent from many threads at once come
back as the PyTorch look gives them, batched; oversized, slow, malformed and too many requests get clear answers
before their bodies are read; memory stays bounded and the server stays up.

Two applications share one proxy: ``/`` (batches of up to 4 within 20 ms, 16 requests at once and 16 queued, bodies up
to 4 MiB) and ``/strict`` (one request at once, two admitted in all: Ray Serve counts the request being assigned
among the queued ones; a batch waiting 1.5 s for more), where admission is seen."""

from __future__ import annotations

import http.client
import io
import json
import os
import socket
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg

pytestmark = pytest.mark.xdist_group("ray")  # one Ray cluster at a time: these run in one worker, in turn

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples" / "serving"))

from client import get_json, post, random_frame  # noqa: E402
from frames import decode_image, pack_frame, unpack_frame  # noqa: E402

LOOK = tg.PostFX(exposure={"speed": 1.5}, grade={"contrast": 15, "saturation": 10}, tonemap="aces").eval()
FORMAT = dict(input_dtype=torch.uint8, layout="NHWC", output="srgb8")
SIZES = [(37, 53)] * 8 + [(20, 31)] * 4
MAX_BYTES = 4 << 20
TIMEOUT_S = 20.0
"""The proxy's request timeout. Two 19 MiB frames of the memory test take about 8 s to be answered on a quiet 2-core
machine and more while the suite's other worker computes: a shorter timeout answered them 408."""


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return tg.onnx.export(LOOK, tmp_path_factory.mktemp("serving") / "look.onnx", **FORMAT)


@pytest.fixture(scope="module")
def url(model):
    """Ray Serve's proxy and both applications (``serve.py``'s ``start_proxy`` and ``deploy``, as its command runs them)."""
    import ray
    from ray import serve

    import serve as example

    address = example.start_proxy(port=_free_port(), timeout_s=TIMEOUT_S)
    try:
        example.deploy(model, max_batch=4, wait_ms=20, max_ongoing=16, max_queued=16, max_bytes=MAX_BYTES, threads=1)
        example.deploy(model, name="strict", route_prefix="/strict", max_batch=64, wait_ms=1500, max_ongoing=1,
                       max_queued=2, max_bytes=64 << 20, threads=1)
        for path in ("/stats", "/strict/stats"):
            _wait_until_up(address + path)
        yield address
    finally:
        serve.shutdown()
        ray.shutdown()


def _wait_until_up(address: str) -> None:
    deadline = time.time() + 60
    while True:
        try:
            get_json(address)
            return
        except OSError:
            if time.time() > deadline:
                raise
            time.sleep(0.2)


def expected_codes(codes: np.ndarray) -> np.ndarray:
    """The PyTorch look on a frame of 8-bit sRGB codes, as 8-bit codes (a still: instant adaptation)."""
    linear = tg.onnx.decode_frame(torch.from_numpy(codes).permute(2, 0, 1)[None], torch.uint8)
    return tg.onnx.encode_frame(tg.onnx.reference(LOOK, linear)[0], "srgb8")[0].permute(1, 2, 0).numpy()


def send_together(url: str, bodies: list, path: str = "/frame") -> list:
    """``(status, answer)`` of each body, all posted at once from a thread each."""
    answers, start = [None] * len(bodies), threading.Barrier(len(bodies))

    def send(index):
        start.wait()
        answers[index] = post(url + path, bodies[index])

    threads = [threading.Thread(target=send, args=(index,)) for index in range(len(bodies))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return answers


def status_before_body(url: str, path: str, length: int, headers=()) -> tuple:
    """Send a request's headers only, declaring ``length`` body bytes, and read the answer: what a server says
    before it reads a body (``None``, ``""`` where it waits for the body)."""
    host = url.split("//")[1]
    connection = http.client.HTTPConnection(host, timeout=TIMEOUT_S + 5)
    try:
        connection.putrequest("POST", path)
        connection.putheader("Content-Length", str(length))
        for name, value in headers:
            connection.putheader(name, value)
        connection.endheaders()
        answer = connection.getresponse()
        return answer.status, answer.read().decode()
    finally:
        connection.close()


def test_concurrent_frames_come_back_batched_and_as_the_look_gives_them(url):
    frames = [random_frame(height, width, "uint8", seed) for seed, (height, width) in enumerate(SIZES)]
    before = get_json(url + "/stats")
    answers = send_together(url, [pack_frame(frame) for frame in frames])
    for frame, (status, body) in zip(frames, answers):
        assert status == 200, body
        graded = unpack_frame(body)
        assert graded.dtype == np.uint8 and graded.shape == frame.shape
        assert np.abs(graded.astype(int) - expected_codes(frame)).max() <= 1
    stats = get_json(url + "/stats")
    frames_run, batches = stats["frames"] - before["frames"], stats["batches"] - before["batches"]
    assert frames_run == len(frames) and batches < frames_run  # batched: fewer batches than frames
    assert stats["latency_ms_p50"] > 0


def test_png_and_exr_files_are_served_and_decoded_without_a_warning(url, tmp_path):
    from PIL import Image

    codes = random_frame(37, 53, "uint8", 7)
    png = io.BytesIO()
    Image.fromarray(codes, "RGB").save(png, format="PNG")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # NumPy's "not writable" warning was printed at the first PNG
        decode_image(png.getvalue(), tg.onnx.frame_format(**FORMAT), 1 << 20)
    status, body = post(url + "/image", png.getvalue())
    assert status == 200 and np.abs(unpack_frame(body).astype(int) - expected_codes(codes)).max() <= 1
    exr = tmp_path / "scene.exr"
    tg.io.write_exr(exr, tg.scene.demo_scene(37, 53)[0] / 8.0)
    status, body = post(url + "/image", exr.read_bytes())
    as_read = tg.onnx.model_input(tg.io.read_exr(exr, to_rec709=True)[None], tg.onnx.frame_format(**FORMAT))[0].numpy()
    assert status == 200 and np.abs(unpack_frame(body).astype(int) - expected_codes(as_read)).max() <= 1


def test_malformed_and_oversized_requests_get_clear_answers(url):
    """400 for a malformed frame, a frame of the wrong dtype, an image over the pixel budget and an unreadable
    Content-Length (the standard library's server closed such a connection without an answer); 413 for a declared
    length over the budget and 411 without one, both before a byte of the body is read; 404 elsewhere."""
    assert post(url + "/frame", b"TGF2" + bytes(12))[0] == 400
    assert b"uint8" in post(url + "/frame", pack_frame(random_frame(4, 4, "float32")))[1]
    big_header = b"TGF1" + (50_000).to_bytes(4, "little") * 2 + b"|u1\0"
    status, answer = post(url + "/frame", big_header)
    assert status == 400 and "pixel budget" in answer.decode()
    assert status_before_body(url, "/frame", 1 << 40)[0] == 413
    assert status_before_body(url, "/frame", MAX_BYTES + 1)[0] == 413
    assert status_before_body(url, "/frame", 0, [("Content-Length", "abc")])[0] == 400
    connection = http.client.HTTPConnection(url.split("//")[1], timeout=10)
    connection.putrequest("POST", "/frame")
    connection.putheader("Transfer-Encoding", "chunked")
    connection.endheaders()
    assert connection.getresponse().status == 411
    connection.close()
    assert post(url + "/nowhere", b"")[0] == 404
    refused = get_json(url + "/stats")["refused"]
    assert refused.get("refused_413", 0) >= 2 and refused.get("refused_411", 0) >= 1


def test_slow_clients_hold_nothing_that_others_need(url):
    """100 connections that send half their headers and stop, and one that sends its headers and half a body and
    stops: a normal request is answered meanwhile, and the stalled body is answered 408 after the timeout."""
    host, port = url.split("//")[1].split(":")
    stalled = []
    for _ in range(100):
        connection = socket.create_connection((host, int(port)))
        connection.sendall(b"POST /frame HTTP/1.1\r\nHost: x\r\nContent-Le")
        stalled.append(connection)
    frame = pack_frame(random_frame(20, 31, "uint8"))
    try:
        started = time.time()
        assert post(url + "/frame", frame)[0] == 200
        assert time.time() - started < 5
        half = socket.create_connection((host, int(port)))
        half.sendall(b"POST /frame HTTP/1.1\r\nHost: x\r\nContent-Length: %d\r\n\r\n" % len(frame) + frame[: len(frame) // 2])
        half.settimeout(TIMEOUT_S + 20)
        answer = half.recv(4096)
        half.close()
        assert answer.startswith(b"HTTP/1.1 408"), answer[:200]
    finally:
        for connection in stalled:
            connection.close()
    assert post(url + "/frame", frame)[0] == 200


def test_requests_beyond_the_queue_get_503_before_their_bodies_are_read(url):
    """The strict application: one request at the replica (its batch waits 1.5 s for more) and two queued; of five
    frames sent together two to four are graded (Ray Serve's count of queued requests is its router's, taken as they
    are assigned) and the rest refused at once. A 60 MB request sent to a full queue is answered 503 from its headers: its body is
    never sent."""
    frames = [pack_frame(random_frame(9, 11, "uint8", seed)) for seed in range(6)]
    answers, start = [None] * len(frames), threading.Barrier(len(frames))

    def send(index):
        start.wait()
        started = time.perf_counter()
        status, _ = post(url + "/strict/frame", frames[index])
        answers[index] = (status, time.perf_counter() - started)

    senders = [threading.Thread(target=send, args=(index,)) for index in range(len(frames))]
    for sender in senders:
        sender.start()
    for sender in senders:
        sender.join()
    graded = [seconds for status, seconds in answers if status == 200]
    refused = [seconds for status, seconds in answers if status == 503]
    assert len(graded) + len(refused) == len(frames) and 2 <= len(graded) <= 4, answers
    assert max(refused) < 1.0 < min(graded), answers  # refused at once; graded after its batch's 1.5 s wait
    holders = [threading.Thread(target=post, args=(url + "/strict/frame", frames[0])) for _ in range(3)]
    for holder in holders:  # one at the replica, then two queued behind it
        holder.start()
        time.sleep(0.3)
    assert status_before_body(url, "/strict/frame", 60 << 20)[0] == 503
    for holder in holders:
        holder.join()


def _resident_mib(name: str) -> float:
    """The resident memory of the processes whose command line holds ``name`` (Ray names its actors' processes)."""
    total = 0
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
                if name.encode() not in cmdline.read():
                    continue
            with open(f"/proc/{pid}/statm") as statm:
                total += int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        except OSError:
            continue
    return total / 2**20


def test_memory_stays_bounded_under_many_large_requests(url):
    """40 connections sending 20 MiB frames at once to the strict application (the standard library's server read
    every body first: 309 MB to 2.73 GB): two are admitted, the rest refused from their headers; the proxy and the
    replica grow by about what two frames and their batch take, and the server answers afterwards."""
    large = pack_frame(random_frame(2600, 2600, "uint8"))  # 19.3 MiB
    before = {name: _resident_mib(name) for name in ("ray::ProxyActor", "ray::ServeReplica:strict")}
    statuses, peaks, done = [], dict(before), threading.Event()

    def sample():
        while not done.is_set():
            for name in peaks:
                peaks[name] = max(peaks[name], _resident_mib(name))
            time.sleep(0.05)

    def send():
        try:
            statuses.append(post(url + "/strict/frame", large, timeout=120)[0])
        except OSError:  # the proxy answered 503 and closed while the body was still being sent
            statuses.append(503)

    sampler = threading.Thread(target=sample)
    sampler.start()
    senders = [threading.Thread(target=send) for _ in range(40)]
    for sender in senders:
        sender.start()
    for sender in senders:
        sender.join()
    done.set()
    sampler.join()
    assert statuses.count(200) >= 2 and statuses.count(503) >= 30, sorted(statuses)
    growth = {name: peaks[name] - before[name] for name in peaks}
    assert growth["ray::ProxyActor"] < 400 and growth["ray::ServeReplica:strict"] < 1600, growth
    assert get_json(url + "/strict/stats")["frames"] >= 2
    assert post(url + "/frame", pack_frame(random_frame(20, 31, "uint8")))[0] == 200


def test_a_model_whose_other_inputs_are_required_is_refused(tmp_path):
    from replica import Looks

    path = tg.onnx.export(LOOK, tmp_path / "plain.onnx", optional_inputs=False)
    with pytest.raises(ValueError, match=r"requires \['adapted', 'dt'\]"):
        Looks.func_or_class(str(path), MAX_BYTES, 1 << 20, 1, {"max_batch": 1, "wait_ms": 0.0}) \
            if hasattr(Looks, "func_or_class") else Looks(str(path), MAX_BYTES, 1 << 20, 1, {"max_batch": 1, "wait_ms": 0.0})
