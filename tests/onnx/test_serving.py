"""examples/serving on Ray Serve, on the loopback address: frames and image files sent from many threads at once come
back as the PyTorch look gives them, batched; oversized, slow, malformed, hostile and too many requests get clear
answers before their bodies are read or decoded; memory stays within the replica's budget and the server stays up.

Two applications share one proxy: ``/`` (a float-input model; batches of up to 4 within 20 ms, 16 requests at once and
16 queued, bodies up to 4 MiB, a 2 s grace before a body must keep up with 128 KiB/s, a :data:`MEMORY_MIB` budget) and
``/strict`` (a model of 8-bit codes; one request at once, two admitted in all: Ray Serve counts the request being
assigned among the queued ones; a batch waiting 1.5 s for more), where admission is seen."""

from __future__ import annotations

import http.client
import json
import math
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg

pytestmark = pytest.mark.xdist_group("ray")  # one Ray cluster at a time: these run in one worker, in turn

ROOT = Path(__file__).resolve().parents[2]
EXR_DIR = ROOT.parent / "shared" / "data" / "exr"
sys.path.insert(0, str(ROOT / "examples" / "serving"))

from client import get_json, post, random_frame, read_answer, trickle  # noqa: E402
from frames import pack_frame, unpack_frame  # noqa: E402
from images import encode_png  # noqa: E402
from test_serving_images import HOSTILE  # noqa: E402

LOOK = tg.PostFX(exposure={"speed": 1.5}, grade={"contrast": 15, "saturation": 10}, tonemap="aces").eval()
LIGHT = dict(input_dtype=torch.float32, layout="NHWC", output="srgb8")
CODES = dict(input_dtype=torch.uint8, layout="NHWC", output="srgb8")
SIZES = [(37, 53)] * 8 + [(20, 31)] * 4
MAX_BYTES = 4 << 20
MEMORY_MIB = 1152
"""The ``/`` replica's memory budget: it holds about 550 MiB idle and leaves 64 for glibc; of the rest half is for the
requests (a few of the sample frames at once), half for the batch being graded."""
STRICT_MEMORY_MIB = 1536
TIMEOUT_S = 20.0
"""The proxy's request timeout. Two 19 MiB frames of the memory test took about 8 s to be answered on a quiet 2-core
machine and more while the suite's other worker computes: a shorter timeout answered them 408."""
BODY_GRACE_S = 2.0
"""Seconds a body may take to start before it must keep up with the minimum rate: Ray's proxy on a 2-core machine
running the rest of the suite forwarded none of a 329 KB body within 0.5 s (408 for a normal client)."""


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("serving")
    return {name: tg.onnx.export(LOOK, folder / f"{name}.onnx", **fmt) for name, fmt in (("light", LIGHT), ("codes", CODES))}


@pytest.fixture(scope="module")
def url(models):
    """Ray Serve's proxy and both applications (``serve.py``'s ``start_proxy`` and ``deploy``, as its command runs them)."""
    import ray
    from ray import serve

    import serve as example

    os.environ.setdefault("RAY_worker_register_timeout_seconds", "300")  # a worker took over 60 s to start on a loaded machine
    address = example.start_proxy(port=_free_port(), timeout_s=TIMEOUT_S)
    try:
        example.deploy(models["light"], max_batch=4, wait_ms=20, max_ongoing=16, max_queued=16, max_bytes=MAX_BYTES,
                       timeout_s=TIMEOUT_S, memory_mib=MEMORY_MIB, body_grace_s=BODY_GRACE_S, threads=1)
        example.deploy(models["codes"], name="strict", route_prefix="/strict", max_batch=64, wait_ms=1500, max_ongoing=1,
                       max_queued=2, max_bytes=64 << 20, timeout_s=TIMEOUT_S, memory_mib=STRICT_MEMORY_MIB,
                       body_grace_s=BODY_GRACE_S, threads=1)
        for path in ("/stats", "/strict/stats"):
            _wait_until_up(address + path)
        yield address
    finally:
        serve.shutdown()
        ray.shutdown()


def _wait_until_up(address: str) -> None:
    deadline = time.time() + 120
    while True:
        try:
            get_json(address)
            return
        except OSError:
            if time.time() > deadline:
                raise
            time.sleep(0.2)


def graded(linear: np.ndarray) -> np.ndarray:
    """The PyTorch look on a ``(height, width, 3)`` frame of linear light, as 8-bit codes (a still: instant
    adaptation)."""
    return tg.onnx.encode_frame(tg.onnx.reference(LOOK, torch.from_numpy(linear).permute(2, 0, 1)[None])[0],
                                "srgb8")[0].permute(1, 2, 0).numpy()


def graded_codes(codes: np.ndarray) -> np.ndarray:
    """The PyTorch look on a frame of 8-bit sRGB codes, as 8-bit codes."""
    linear = tg.onnx.decode_frame(torch.from_numpy(codes).permute(2, 0, 1)[None], torch.uint8)
    return graded(linear[0].permute(1, 2, 0).numpy())


def within_a_code(answer: bytes, expected: np.ndarray) -> bool:
    frame = unpack_frame(answer)
    return frame.dtype == np.uint8 and frame.shape == expected.shape and np.abs(frame.astype(int) - expected).max() <= 1


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
    frames = [random_frame(height, width, "float32", seed) for seed, (height, width) in enumerate(SIZES)]
    before = get_json(url + "/stats")
    answers = send_together(url, [pack_frame(frame) for frame in frames])
    for frame, (status, body) in zip(frames, answers):
        assert status == 200 and within_a_code(body, graded(frame)), body[:200]
    stats = get_json(url + "/stats")
    frames_run, batches = stats["frames"] - before["frames"], stats["batches"] - before["batches"]
    assert frames_run == len(frames) and batches < frames_run  # batched: fewer batches than frames
    assert stats["latency_ms_p50"] > 0


def sample_files() -> dict:
    """Real frames as a client sends them: two sample EXRs and PNGs of their sRGB codes; ``{name: (body, expected
    codes)}``."""
    files = {}
    for name in ("Carrots", "Desk"):
        light = tg.io.read_exr(EXR_DIR / f"{name}.exr", to_rec709=True)[:3]
        files[f"{name}.exr"] = ((EXR_DIR / f"{name}.exr").read_bytes(), graded(light.permute(1, 2, 0).numpy()))
        codes = tg.onnx.model_input(light[None], tg.onnx.frame_format(**CODES))[0].numpy()
        files[f"{name}.png"] = (encode_png(codes), graded_codes(codes))
    return files


def test_png_and_exr_files_are_served_to_the_model_that_takes_them(url):
    """Both to the float model; the PNG to the model of codes as its codes, the EXR refused there, naming the export
    that takes light (it would have clipped the scene at 1.0)."""
    files = sample_files()
    for name, (body, expected) in files.items():
        status, answer = post(url + "/image", body)
        assert status == 200 and within_a_code(answer, expected), (name, answer[:200])
    status, answer = post(url + "/strict/image", files["Carrots.png"][0])
    assert status == 200 and within_a_code(answer, files["Carrots.png"][1])
    status, answer = post(url + "/strict/image", files["Carrots.exr"][0])
    assert status == 400 and "float input for EXR frames" in json.loads(answer)["error"]


def test_malformed_and_oversized_requests_get_clear_answers(url):
    """400 for a malformed frame, a frame of the wrong dtype, an image over the pixel budget and an unreadable
    Content-Length (the standard library's server closed such a connection without an answer); 413 for a declared
    length over the budget and 411 without one, both before a byte of the body is read; 404 elsewhere."""
    assert post(url + "/frame", b"TGF2" + bytes(12))[0] == 400
    assert b"float32" in post(url + "/frame", pack_frame(random_frame(4, 4, "uint8")))[1]
    big_header = b"TGF1" + (50_000).to_bytes(4, "little") * 2 + b"<f4\0"
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


def test_hostile_and_unsupported_images_get_400_with_a_short_reason_and_no_server_path(url):
    """A 65-byte PNG declaring 30000x30000 (Pillow's DecompressionBombError made it a 500), a truncated PNG, garbage
    image data, a 0x0, a 16-bit, a palette and a grey PNG, a damaged header, other formats, and damaged EXRs."""
    damaged = sorted((EXR_DIR / "damaged").glob("*_exr"))[:6]
    cases = [(name, body, reason) for name, (body, reason) in HOSTILE.items()]
    cases += [(path.name, path.read_bytes(), "") for path in damaged]
    for name, body, reason in cases:
        status, answer = post(url + "/image", body)
        error = json.loads(answer)["error"]
        assert status == 400 and reason in error and len(error) < 400, (name, status, answer[:300])
        assert "/tmp" not in error and "torchgrade-serve" not in error and "frame.exr" not in error, (name, error)
    assert post(url + "/frame", pack_frame(random_frame(5, 6, "float32")))[0] == 200


def test_clients_trickling_bodies_lose_their_slots_not_others(url):
    """24 connections sending a frame a byte every 0.1 s, each reconnecting when answered, hold more than the 16
    requests the replica takes at once: each is answered 408 once it falls behind the minimum rate (after the 2 s
    grace) and its slot goes to the next; normal requests sent meanwhile are all graded (starved, the proxy would
    have answered them 408 after 20 s)."""
    stop, answers = threading.Event(), [[] for _ in range(24)]
    slow_body = pack_frame(random_frame(32, 32, "float32", 5))
    tricklers = [threading.Thread(target=lambda index=index: answers[index].extend(trickle(url, "/frame", slow_body, stop)))
                 for index in range(24)]
    before = get_json(url + "/stats")["refused"].get("refused_408", 0)
    for trickler in tricklers:
        trickler.start()
    try:
        while get_json(url + "/stats")["refused"].get("refused_408", 0) < before + 16:  # the first 16 held their slots
            time.sleep(0.1)
        frames = [random_frame(24, 40, "float32", seed) for seed in range(3)]
        normal = [post(url + "/frame", pack_frame(frame)) for frame in frames]
    finally:
        stop.set()
        for trickler in tricklers:
            trickler.join()
    for frame, (status, body) in zip(frames, normal):
        assert status == 200 and within_a_code(body, graded(frame)), body[:200]
    every = [answer for each in answers for answer in each]
    assert len(every) >= 16
    assert all(answer.startswith(b"HTTP/1.1 408") and b"slower than 131072 bytes a second" in answer for answer in every)


def test_sixteen_clients_sending_real_frames_are_all_graded_within_the_memory_budget(url):
    """Sample EXRs and PNGs of them, 16 at once: each request waits until what it holds fits the budget, so some
    wait; every one is answered 200 with its graded frame, and the replica's peak resident memory stays under the
    budget."""
    files = list(sample_files().values())
    before = get_json(url + "/stats")["memory"]["waited"]
    chosen = [files[index % len(files)] for index in range(16)]
    answers = send_together(url, [body for body, _ in chosen], "/image")
    for (_, expected), (status, answer) in zip(chosen, answers):
        assert status == 200 and within_a_code(answer, expected), answer[:200]
    stats = get_json(url + "/stats")
    assert stats["memory"]["waited"] > before and stats["memory"]["held_mib"] == 0.0
    assert stats["peak_rss_mib"] <= MEMORY_MIB, stats


def test_stats_answer_while_a_batch_is_graded(url):
    """Grading runs on a thread of its own: /stats, asked while a 1.2-megapixel frame is graded, sees it running."""
    ramp = np.linspace(0, 255, 1100).astype(np.uint8)
    rows, columns = np.meshgrid(ramp, ramp, indexing="ij")
    png = encode_png(np.stack([rows, columns, rows[::-1]], 2))
    answer = []
    sender = threading.Thread(target=lambda: answer.append(post(url + "/image", png)))
    sender.start()
    running = []
    while sender.is_alive():
        running.append(get_json(url + "/stats")["running"])
    sender.join()
    assert answer[0][0] == 200 and max(running) == 1, (answer[0][0], running)


def test_slow_headers_hold_nothing_and_a_stalled_body_loses_its_slot(url):
    """100 connections that send half their headers and stop, and one that sends its headers and half a body and
    stops: a normal request is answered meanwhile, and the stalled body is answered 408 by the replica once it falls
    behind the minimum rate."""
    host, port = url.split("//")[1].split(":")
    stalled = []
    for _ in range(100):
        connection = socket.create_connection((host, int(port)))
        connection.sendall(b"POST /frame HTTP/1.1\r\nHost: x\r\nContent-Le")
        stalled.append(connection)
    frame = pack_frame(random_frame(20, 31, "float32"))
    try:
        assert post(url + "/frame", frame)[0] == 200
        half = socket.create_connection((host, int(port)))
        half.sendall(b"POST /frame HTTP/1.1\r\nHost: x\r\nContent-Length: %d\r\n\r\n" % len(frame) + frame[: len(frame) // 2])
        answer = read_answer(half, TIMEOUT_S + 20)
        half.close()
        assert answer.startswith(b"HTTP/1.1 408") and b"slower than" in answer, answer[:200]
    finally:
        for connection in stalled:
            connection.close()
    assert post(url + "/frame", frame)[0] == 200


def test_requests_beyond_the_queue_get_503_before_their_bodies_are_read(url):
    """The strict application: one request at the replica (its batch waits 1.5 s for more) and two queued; of five
    frames sent together two to four are graded (Ray Serve's count of queued requests is its router's, taken as they
    are assigned) and the rest refused with 503. A 60 MB request sent to a full queue is answered 503 from its headers: its body is
    never sent."""
    frames = [pack_frame(random_frame(9, 11, "uint8", seed)) for seed in range(6)]
    answers, start = [None] * len(frames), threading.Barrier(len(frames))

    def send(index):
        start.wait()
        answers[index] = post(url + "/strict/frame", frames[index])[0]

    senders = [threading.Thread(target=send, args=(index,)) for index in range(len(frames))]
    for sender in senders:
        sender.start()
    for sender in senders:
        sender.join()
    assert set(answers) <= {200, 503} and 2 <= answers.count(200) <= 4, answers
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
    """40 connections sending frames of up to 7.3 MiB at once to the strict application (the standard library's server
    read every body first: 309 MB to 2.73 GB): two are admitted, the rest refused from their headers; the proxy grows by
    about what two frames take, the replica's peak stays under its budget, and the server answers afterwards. The side
    is at most 1600 and within the pixel budget the replica set from the memory it measured at start (the cost of a
    pixel moved from 229 to 324 bytes between runs: a fixed 1600x1600 frame was then refused 400)."""
    side = min(1600, math.isqrt(int(0.9 * get_json(url + "/strict/model")["max_pixels"])))
    large = pack_frame(random_frame(side, side, "uint8"))
    before = _resident_mib("ray::ProxyActor")
    statuses, peak, done = [], [before], threading.Event()

    def sample():
        while not done.is_set():
            peak[0] = max(peak[0], _resident_mib("ray::ProxyActor"))
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
    stats = get_json(url + "/strict/stats")
    assert peak[0] - before < 400 and stats["peak_rss_mib"] <= STRICT_MEMORY_MIB, (peak[0] - before, stats)
    assert stats["frames"] >= 2
    assert post(url + "/frame", pack_frame(random_frame(20, 31, "float32")))[0] == 200


def test_a_model_whose_other_inputs_are_required_is_refused(tmp_path):
    from limits import Limits
    from replica import Looks

    path = tg.onnx.export(LOOK, tmp_path / "plain.onnx", optional_inputs=False)
    with pytest.raises(ValueError, match=r"requires \['adapted', 'dt'\]"):
        Looks(str(path), Limits(), threads=1)


def test_the_command_says_when_its_port_is_in_use(models):
    """One line and status 1 (Serve's proxy failing to bind ended in an ActorDiedError that did not say why)."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = subprocess.run([sys.executable, str(ROOT / "examples" / "serving" / "serve.py"), str(models["light"]),
                               "--port", str(port)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and done.stderr.strip().splitlines() == [
        f"serve.py: cannot serve on 127.0.0.1:{port}: the port is in use (choose another with --port)"], done.stderr
