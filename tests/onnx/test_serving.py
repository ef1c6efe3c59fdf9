"""examples/serving: the batching server on localhost, a look with eye adaptation served as stills; frames and image
files sent from many threads at once come back as the PyTorch look gives them, batched; memory and the queue stay bounded."""

from __future__ import annotations

import http.client
import io
import json
import select
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples" / "serving"))

from client import get_json, post, random_frame  # noqa: E402
from server import make_server, pack_frame, unpack_frame  # noqa: E402

LOOK = tg.PostFX(exposure={"speed": 1.5}, grade={"contrast": 15, "saturation": 10}, tonemap="aces").eval()
FORMAT = dict(input_dtype=torch.uint8, layout="NHWC", output="srgb8")
SIZES = [(37, 53)] * 8 + [(20, 31)] * 4


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return tg.onnx.export(LOOK, tmp_path_factory.mktemp("serving") / "look.onnx", **FORMAT)


@pytest.fixture(scope="module")
def url(model):
    """The server in a process of its own (its memory is its own), on a free port it prints."""
    server = subprocess.Popen([sys.executable, str(ROOT / "examples" / "serving" / "server.py"), str(model), "--port", "0",
                               "--max-batch", "4", "--wait-ms", "20", "--threads", "1"],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert select.select([server.stdout], [], [], 60)[0], "the server printed nothing in 60 s"
        line = server.stdout.readline()
        assert line.startswith("serving"), line
        yield line.split(" on ")[1].split()[0]
    finally:
        server.terminate()
        server.wait(timeout=10)


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
    assert frames_run == len(frames) and batches < frames_run  # two sizes: at least 2 batches, at most 4 frames each
    assert stats["latency_ms_p50"] > 0 and stats["throughput_fps"] > 0


def test_png_and_exr_files_are_served(url, tmp_path):
    from PIL import Image

    codes = random_frame(37, 53, "uint8", 7)
    png = io.BytesIO()
    Image.fromarray(codes, "RGB").save(png, format="PNG")
    status, body = post(url + "/image", png.getvalue())
    assert status == 200 and np.abs(unpack_frame(body).astype(int) - expected_codes(codes)).max() <= 1
    exr = tmp_path / "scene.exr"
    tg.io.write_exr(exr, tg.scene.demo_scene(37, 53)[0] / 8.0)
    status, body = post(url + "/image", exr.read_bytes())
    as_read = tg.onnx.model_input(tg.io.read_exr(exr, to_rec709=True)[None], tg.onnx.frame_format(**FORMAT))[0].numpy()
    assert status == 200 and np.abs(unpack_frame(body).astype(int) - expected_codes(as_read)).max() <= 1


def test_memory_stays_bounded_and_bad_requests_are_refused(url):
    frame = pack_frame(random_frame(128, 128, "uint8"))
    for _ in range(3):
        send_together(url, [frame] * 8)  # warm: onnxruntime's arenas at every batch size
    before = get_json(url + "/stats")["rss_mib"]
    for _ in range(15):
        assert {status for status, _ in send_together(url, [frame] * 8)} == {200}
    stats = get_json(url + "/stats")
    # 120 frames of 48 KiB each way: keeping a request's frames would grow it 11 MiB; measured growth 0.1 to 1.9 MiB
    assert stats["rss_mib"] - before < 6, (before, stats)
    assert stats["pending"] == 0
    assert post(url + "/frame", b"TGF2" + bytes(12))[0] == 400
    assert b"uint8" in post(url + "/frame", pack_frame(random_frame(4, 4, "float32")))[1]
    connection = http.client.HTTPConnection(url.split("//")[1], timeout=10)
    connection.putrequest("POST", "/frame")
    connection.putheader("Content-Length", str(1 << 40))
    connection.endheaders()
    assert connection.getresponse().status == 413
    connection.close()


def test_frames_beyond_the_pending_bound_get_503_at_once(model):
    """Two frames admitted (the batch waits 1.5 s for more), the three others refused without waiting."""
    server, batcher = make_server(model, port=0, max_batch=64, wait_ms=1500, max_pending=2, threads=1)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}"
        answers = send_together(url, [pack_frame(random_frame(9, 11, "uint8", seed)) for seed in range(5)])
        assert sorted(status for status, _ in answers) == [200, 200, 503, 503, 503]
        assert json.loads(next(body for status, body in answers if status == 503))["error"] == "2 frames pending"
        assert get_json(url + "/stats")["rejected"] == 3
    finally:
        server.shutdown()
        server.server_close()
        batcher.stop()


def test_a_model_whose_other_inputs_are_required_is_refused(tmp_path):
    path = tg.onnx.export(LOOK, tmp_path / "plain.onnx", optional_inputs=False)
    with pytest.raises(ValueError, match=r"requires \['adapted', 'dt'\]"):
        make_server(path, port=0)
