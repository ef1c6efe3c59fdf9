"""The serving example's parts without a server: a body read against its minimum rate (``body.py``), the memory
budget requests wait in line for (``memory.py``), the limits (``limits.py``), the port check (``serve.py``), and the
replica's batches leaving out frames no one waits for (``replica.py``)."""

from __future__ import annotations

import asyncio
import re
import socket
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

import torchgrade as tg

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples" / "serving"))

from body import Body, Refused  # noqa: E402
from limits import Limits  # noqa: E402
from memory import Cost, MemoryBudget, OverBudget  # noqa: E402
from serve import check_port_free  # noqa: E402


class Sent:
    """A request whose body comes as ``chunks``, ``delay`` seconds apart (what ``Body`` reads of a request)."""

    def __init__(self, chunks: list, delay: float = 0.0):
        self.chunks, self.delay = chunks, delay

    async def stream(self):
        for chunk in self.chunks:
            await asyncio.sleep(self.delay)
            yield chunk


def read(chunks: list, delay: float = 0.0, length: int | None = None, wait_s: float = 0.0, paused: bool = False,
         min_rate: float = 1000.0, grace_s: float = 0.2, timeout_s: float = 60.0):
    """The whole body as ``Body`` reads it, or the ``Refused`` it raises; ``wait_s`` seconds pass after its first byte
    (a wait for memory), left out of its time where ``paused``; the request is answered 408 ``timeout_s`` after it
    came."""
    async def whole():
        body = Body(Sent(chunks, delay), sum(map(len, chunks)) if length is None else length, min_rate, grace_s,
                    time.monotonic() + timeout_s)
        await body.head(1)
        await asyncio.sleep(wait_s)
        if paused:
            body.pause(wait_s)
        return bytes(await body.whole())

    try:
        return asyncio.run(whole())
    except Refused as refused:
        return refused


def test_a_body_that_keeps_pace_is_read_whole():
    assert read([b"TGF1", bytes(3000), b"end"]) == b"TGF1" + bytes(3000) + b"end"
    assert read([b"x"] * 5, delay=0.01) == b"xxxxx"  # slow, but within the grace


def test_a_body_slower_than_the_minimum_rate_is_answered_408():
    refused = read([b"x"] * 200, delay=0.05)  # 20 bytes a second against 1000
    assert isinstance(refused, Refused) and refused.status == 408 and "slower than 1000 bytes a second" in str(refused)


def test_a_body_that_could_not_end_before_its_deadline_is_answered_408_after_the_grace():
    """A large body sent above the minimum rate but too slowly to end before the proxy's timeout held its slot, and the
    memory it reserved, until that timeout (a 27 MB frame at 128 KiB/s: 30 s): it must keep the pace that ends it in
    time, 40,000 bytes in the 0.8 s after the grace here, and is answered 408 once it falls behind."""
    chunks = [bytes(2000)] * 20  # 40,000 bytes at 20,000 bytes a second: twice the minimum rate, four times too slow
    refused = read(chunks, delay=0.1, min_rate=10_000.0, timeout_s=1.0)
    assert isinstance(refused, Refused) and refused.status == 408
    required_rate = float(re.search(r"slower than (\d+) bytes a second", str(refused)).group(1))
    assert required_rate == pytest.approx(50_000, rel=0.01)  # 40,000 bytes in the 0.8 s left, as the clock read it
    assert read([bytes(20_000), bytes(20_000)], delay=0.05, min_rate=10_000.0, timeout_s=1.0) == bytes(40_000)


def test_time_spent_waiting_for_memory_is_not_the_clients():
    """Every byte is there at once, but the replica reads the rest only after a wait longer than the grace."""
    refused = read([b"x", bytes(100)], wait_s=0.5)
    assert isinstance(refused, Refused) and refused.status == 408
    assert read([b"x", bytes(100)], wait_s=0.5, paused=True) == b"x" + bytes(100)


def test_a_body_past_its_length_or_short_of_it_is_refused():
    refused = read([b"abc", b"def"], length=4)
    assert isinstance(refused, Refused) and refused.status == 413
    with pytest.raises(ValueError, match="ended after 3 of the 6 bytes"):
        read([b"abc"], length=6)


def test_the_memory_budget_grants_in_order_and_never_past_its_capacity():
    amounts = [40, 70, 10, 30, 90, 20, 60]
    granted, highest = [], []

    async def request(index, budget):
        async with budget.reserved(amounts[index]):
            granted.append(index)
            highest.append(budget.held)
            await asyncio.sleep(0.01 * (index % 3))

    async def everyone():
        budget = MemoryBudget(100)
        tasks = [asyncio.create_task(request(index, budget)) for index in range(len(amounts))]
        await asyncio.gather(*tasks)
        return budget

    budget = asyncio.run(everyone())
    assert granted == list(range(len(amounts))) and max(highest) <= 100 and budget.held == 0
    assert budget.peak == max(highest) and budget.waited >= 1


def test_a_request_given_up_while_waiting_gives_its_place_and_a_request_past_the_capacity_is_refused():
    async def scene():
        budget = MemoryBudget(100)
        async with budget.reserved(60):
            big_held, small_held = budget.reserved(80), budget.reserved(30)  # kept: a dropped one is closed, and frees
            big, small = asyncio.create_task(big_held.__aenter__()), asyncio.create_task(small_held.__aenter__())
            await asyncio.sleep(0)
            waiting = budget.waiting
            big.cancel()
            await asyncio.wait_for(small, 5.0)
            return waiting, budget.held

    assert asyncio.run(scene()) == (2, 90)
    with pytest.raises(OverBudget, match="more than the 0 MiB"):
        asyncio.run(MemoryBudget(100).reserved(101).__aenter__())


def test_a_cost_is_the_line_through_its_probes_with_its_margin_and_floor():
    cost = Cost.through((100, 1500), (400, 3000), margin=2.0)
    assert cost.per_pixel == 2.0 * 5 and cost.fixed == 2.0 * 1000 and cost.bytes(10) == 2000 + 100
    assert cost.pixels(2000 + 10 * 99 + 9) == 99
    floored = Cost.through((100, 1500), (400, 1200), floor=3.0, margin=1.0)
    assert floored.per_pixel == 3.0 and floored.fixed == 0.0


def test_limits_refuse_nonsense_and_hold_the_pixels_to_the_bytes():
    with pytest.raises(ValueError, match="min_body_rate must be at least 1"):
        Limits(min_body_rate=0)
    assert Limits(max_bytes=3000).max_pixels == 1000 and Limits().max_pixels == min(1 << 26, (64 << 20) // 3)


def test_a_port_in_use_is_reported_as_such():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(OSError, match=f"cannot serve on 127.0.0.1:{port}: the port is in use"):
            check_port_free("127.0.0.1", port)
    check_port_free("127.0.0.1", port)


@pytest.fixture(scope="module")
def replica(tmp_path_factory):
    """The replica of a float-input model, outside Ray Serve (its batches are called directly), and its look."""
    from replica import Looks

    look = tg.PostFX(grade={"contrast": 20}, tonemap="aces").eval()
    model = tg.onnx.export(look, tmp_path_factory.mktemp("replica") / "look.onnx", input_dtype=torch.float32,
                           layout="NHWC", output="srgb8")
    return Looks(str(model), Limits(memory_mib=8192), threads=1), look


def test_the_replica_measures_what_each_kind_of_request_and_a_batch_cost(replica):
    looks, _ = replica
    assert set(looks.decoding) == {"frame", "png", "exr"}
    assert looks.grading.per_pixel >= 12 + 3  # at least the float32 frame and its 8-bit answer
    assert looks.decoding["png"].per_pixel >= 12 and looks.decoding["exr"].per_pixel >= 12
    room = looks.memory.capacity
    assert looks.batch_room == room and looks.max_pixels <= looks.grading.pixels(room)
    assert looks.held("png", 1000, body=500) == 1000 + looks.decoding["png"].bytes(1000) + 6000


def test_what_an_exr_request_reserves_for_decoding_covers_the_costliest_exr_the_server_reads(replica):
    """The probe was a half RGB EXR: a float RGBA EXR in one row of tiles as tall as the image (the costliest the server
    reads, :data:`images.EXR_BYTES_PER_PIXEL`) took twice what an EXR request reserved for its decoding. A peak measured
    here moves from run to run, so the margin is allowed once more."""
    from images import decode_image
    from memory import MARGIN, peak_growth
    from test_serving_images import tiled_exr

    looks, _ = replica
    body = tiled_exr(384, 384, 384)
    decode_image(body, looks.format, looks.max_pixels)  # first-use costs, as the probes pay them
    used = peak_growth(lambda: decode_image(body, looks.format, looks.max_pixels))
    assert used <= MARGIN * looks.decoding["exr"].bytes(384 * 384), (used, looks.decoding["exr"])


def test_the_replica_grades_only_the_frames_someone_waits_for(replica):
    """Of four frames in a batch, one whose request was cancelled and one past its deadline are not graded; the
    others are, as the look gives them."""
    from replica import Ticket

    looks, look = replica
    before = looks.stats()
    frames = [np.random.default_rng(seed).random((9, 13 + seed % 2, 3), np.float32) * 4 for seed in range(4)]
    tickets = [Ticket(frames[0], float("inf")), Ticket(frames[1], float("inf"), gone=True),
               Ticket(frames[2], time.monotonic() - 1.0), Ticket(frames[3], float("inf"))]
    results = looks._run(tickets)
    assert results[1] is None and results[2] is None
    for index in (0, 3):
        linear = torch.from_numpy(frames[index]).permute(2, 0, 1)[None]
        expected = tg.onnx.encode_frame(tg.onnx.reference(look, linear)[0], "srgb8")[0].permute(1, 2, 0).numpy()
        assert np.abs(results[index].astype(int) - expected).max() <= 1
    stats = looks.stats()
    assert [stats[name] - before[name] for name in ("frames", "skipped", "batches")] == [2, 2, 2]


def test_a_batch_whose_grading_would_not_fit_its_room_is_graded_in_parts(replica, monkeypatch):
    from replica import Ticket

    looks, _ = replica
    frames = [np.full((30, 40, 3), 0.1 * seed, np.float32) for seed in range(5)]
    monkeypatch.setattr(looks, "batch_room", looks.grading.bytes(5 * 30 * 40 // 2))  # room for two frames and a half
    before = looks.stats()["batches"]
    results = looks._run([Ticket(frame, float("inf")) for frame in frames])
    assert looks.stats()["batches"] - before == 3 and all(result.shape == (30, 40, 3) for result in results)
    alone = [looks._run([Ticket(frame, float("inf"))])[0] for frame in frames]
    assert all(np.array_equal(result, each) for result, each in zip(results, alone))  # in order, as graded alone


@pytest.mark.parametrize("name", ["frames", "images", "limits", "memory"])
def test_the_examples_docstring_examples_run(name):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(name))
    assert result.attempted > 0 and result.failed == 0
