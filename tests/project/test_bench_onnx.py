"""benchmarks/bench_onnx.py on tiny inputs: a row end to end on the CPU, and the ``--device cuda`` path as far as a
machine without a GPU can take it (the device reaches the runtimes, the results go to their own file)."""

from __future__ import annotations

import sys
from pathlib import Path

import onnxruntime
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchgrade as tg  # noqa: E402
from benchmarks import bench_onnx  # noqa: E402

CUDA_ORT = "CUDAExecutionProvider" in onnxruntime.get_available_providers()


def test_a_cpu_row_times_every_runtime_and_counts_nodes(tmp_path):
    look = tg.PostFX(grade={"contrast": 10}, tonemap="aces").eval()
    row = bench_onnx.measure("tiny", look, torch.rand(1, 3, 8, 12) * 4, tmp_path)
    labels = ("onnxruntime", "onnxruntime_no_spin", "openvino_f32", "openvino_default", "pytorch")
    assert set(row) == {"nodes_traced", "nodes", *(f"{label}_ms" for label in labels)}
    assert row["nodes"] == tg.onnx.node_count(tmp_path / "tiny.onnx") <= row["nodes_traced"]
    assert all(row[f"{label}_ms"] > 0 for label in labels)


def test_each_device_writes_its_own_results_and_columns():
    assert bench_onnx.parse_args([]).device == "cpu"
    assert [bench_onnx.results_stem(device) for device in ("cpu", "cuda")] == ["onnx", "onnx_cuda"]
    row = {"nodes_traced": 9, "nodes": 5, "onnxruntime_ms": 1.5, "pytorch_ms": 2.5}
    report = {"look": "look.json", "device": "cuda", "torch": "x", "threads": 2, "cores": 2, "gpu": "A GPU",
              "load_average": [0.5, 0.7], "results": {"full look": row}, "compile": {}}
    lines = bench_onnx.table(report)
    assert "--device cuda" in lines[2] and "A GPU" in lines[2] and "OpenVINO" not in lines[4]
    assert lines[4] == "| model | nodes as traced | nodes folded | onnxruntime ms | PyTorch eager ms |"
    assert lines[6] == "| full look | 9 | 5 | 1.5 | 2.5 |"
    cpu = bench_onnx.table({**report, "device": "cpu", "results": {}})
    assert "no GPU was available" in cpu[2] and "OpenVINO default ms" in cpu[4]


@pytest.mark.skipif(torch.cuda.is_available(), reason="the refusal is for machines without CUDA")
def test_cuda_run_without_a_gpu_says_so(capsys):
    assert bench_onnx.main(["--device", "cuda"]) == 2
    assert "no CUDA device" in capsys.readouterr().err


@pytest.mark.skipif(CUDA_ORT, reason="this onnxruntime has the CUDA provider")
def test_onnxruntime_on_cuda_without_its_provider_is_an_error_not_a_cpu_run(tmp_path):
    path = tg.onnx.export(tg.ToneMap("reinhard"), tmp_path / "tone.onnx")
    with pytest.raises(ValueError, match="no CUDAExecutionProvider"):
        tg.onnx.session(path, "onnxruntime", device="cuda")
    with pytest.raises(ValueError, match="openvino runs here on cpu"):
        tg.onnx.session(path, "openvino", device="cuda")


def test_a_cuda_session_that_would_run_on_the_cpu_is_an_error(tmp_path, monkeypatch):
    """onnxruntime-gpu lists the CUDA provider even where the CUDA or cuDNN libraries are missing, then logs an error and
    runs on the CPU: the session refuses that. The CPU provider follows CUDA's for nodes CUDA has no kernel for."""
    path = tg.onnx.export(tg.ToneMap("reinhard"), tmp_path / "tone.onnx")
    opened = []

    class FellBack:
        def __init__(self, model, options, providers):
            opened.append(providers)

        def get_providers(self):
            return ["CPUExecutionProvider"]

    monkeypatch.setattr(onnxruntime, "get_available_providers", lambda: ["CUDAExecutionProvider", "CPUExecutionProvider"])
    monkeypatch.setattr(onnxruntime, "InferenceSession", FellBack)
    with pytest.raises(ValueError, match="could not start CUDAExecutionProvider .*runs on CPUExecutionProvider"):
        tg.onnx.session(path, device="cuda:1")
    assert opened == [[("CUDAExecutionProvider", {"device_id": 1}), "CPUExecutionProvider"]]
    for device in ("gpu", "cuda:x", "cpu:0", "cuda:"):
        with pytest.raises(ValueError, match="runs here on"):
            tg.onnx.session(path, device=device)


@pytest.mark.skipif(not (CUDA_ORT and torch.cuda.is_available()), reason="needs a GPU and onnxruntime's CUDA provider")
def test_a_cuda_row_times_onnxruntime_cuda_and_pytorch_cuda(tmp_path):
    look = tg.PostFX(grade={"contrast": 10}, tonemap="aces").eval()
    row = bench_onnx.measure("tiny", look, torch.rand(1, 3, 8, 12) * 4, tmp_path, "cuda")
    assert row["onnxruntime_ms"] > 0 and row["pytorch_ms"] > 0 and "openvino_f32_ms" not in row


def test_onnxruntime_sessions_spin_unless_asked_not_to(tmp_path):
    path = tg.onnx.export(tg.ToneMap("reinhard"), tmp_path / "tone.onnx")
    entries = [tg.onnx.session(path, spin=spin).get_session_options().get_session_config_entry("session.intra_op.allow_spinning")
               for spin in (True, False)]
    assert entries == ["1", "0"]
