"""The benchmark's building blocks on tiny inputs: metrics against known values, and a few rows end to end."""

from __future__ import annotations

import dataclasses
import importlib
import json
import logging
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchgrade as tg  # noqa: E402
from benchmarks import common, lut_floor, metrics  # noqa: E402
from benchmarks.__main__ import NAMES  # noqa: E402
from benchmarks.__main__ import main as door  # noqa: E402
from benchmarks.suite import measure, methods, report, rows, workload  # noqa: E402
from torchgrade.color import linear_to_logc, srgb_to_linear  # noqa: E402


def display_of_codes(codes) -> torch.Tensor:
    """Display-linear ``(1, 3, 1, N)`` pixels whose 8-bit sRGB codes are ``codes`` (an ``(N, 3)`` list)."""
    return srgb_to_linear(torch.tensor(codes, dtype=torch.float64) / 255.0).t().reshape(1, 3, 1, -1)


def test_srgb_codes_clamp_and_encode():
    codes = metrics.srgb_codes(torch.tensor([-1.0, 1.0, 7.0]).reshape(1, 3, 1, 1))
    assert codes.flatten().tolist() == pytest.approx([0.0, 255.0, 255.0])
    assert float(metrics.srgb_codes(display_of_codes([[128, 128, 128]])).mean()) == pytest.approx(128.0)


def test_one_code_shift_is_an_error_of_one():
    reference = metrics.srgb_codes(display_of_codes([[100, 50, 200]] * 1000))
    shifted = metrics.srgb_codes(display_of_codes([[101, 50, 200]] * 1000))
    summary = metrics.code_error_summary(reference, shifted)
    assert summary["max_error_8bit"] == pytest.approx(1.0)
    assert summary["p999_error_8bit"] == pytest.approx(1.0)


def test_p999_ignores_one_outlier_in_ten_thousand():
    reference = torch.zeros(1, 3, 1, 10_000, dtype=torch.float64)
    codes = reference.clone()
    codes[0, 0, 0, 0] = 40.0
    summary = metrics.code_error_summary(reference, codes)
    assert summary["max_error_8bit"] == 40.0 and summary["p999_error_8bit"] == 0.0


def test_delta_e2000_zero_for_identical_and_known_for_grey_steps():
    codes = metrics.srgb_codes(display_of_codes([[10, 200, 30], [255, 255, 255], [0, 0, 0]]))
    assert metrics.delta_e2000(codes, codes) == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)
    # Neutral greys: ΔE2000 reduces to ΔL / S_L with S_L = 1 at L* = 50 (CIE 2000 lightness weighting).
    grey_a, grey_b = (display_of_codes([[v, v, v]]) for v in (118, 119))
    lightness = [metrics.colour.XYZ_to_Lab(metrics.colour.sRGB_to_XYZ(metrics.pixels_of(metrics.srgb_codes(g))), metrics.D65)[0, 0]
                 for g in (grey_a, grey_b)]
    expected = abs(lightness[1] - lightness[0]) / (1 + 0.015 * (sum(lightness) / 2 - 50) ** 2 / (20 + (sum(lightness) / 2 - 50) ** 2) ** 0.5)
    assert float(metrics.delta_e2000(metrics.srgb_codes(grey_a), metrics.srgb_codes(grey_b))[0]) == pytest.approx(expected, rel=1e-6)


def test_sample_indices_are_distinct_and_fixed():
    first, again = metrics.sample_indices(1000, 100), metrics.sample_indices(1000, 100)
    assert torch.equal(first, again) and first.unique().numel() == 100
    assert torch.equal(metrics.sample_indices(5, 10), torch.arange(5))


def test_peak_rss_counts_a_new_buffer():
    size_mb = common.peak_rss_mb(lambda: torch.ones(8 * 2**20 // 4))  # 8 MiB, written
    if size_mb is None:
        pytest.skip("no /proc/self/clear_refs")
    assert size_mb >= 7.0


def test_pareto_front_keeps_only_undominated_points():
    points = [(1.0, 10.0, "fast"), (2.0, 12.0, "dominated"), (3.0, 1.0, "accurate"), (5.0, 0.5, "slowest")]
    assert [name for _, _, name in report.pareto_front(points)] == ["fast", "accurate", "slowest"]


def test_downscale_averages_by_an_integer_factor():
    image = torch.arange(16.0).reshape(1, 1, 4, 4)
    assert workload.downscale(image, 2).flatten().tolist() == [2.5, 4.5, 10.5, 12.5]
    assert workload.downscale(image, None) is image


@pytest.fixture(scope="module")
def tiny_work(tmp_path_factory):
    """The benchmark's workload on tiny images: accuracy scenes at most 24 pixels a side, a 48×64 frame."""
    patch = pytest.MonkeyPatch()
    patch.setattr(workload, "FRAME", (48, 64))
    patch.setattr(workload, "DEMO_SIZE", (36, 64))
    patch.setattr(workload, "BATCHES", (1, 2))
    patch.setattr(workload, "BATCH_SIDE", 16)
    plan = dataclasses.replace(workload.Plan.of(quick=True, out=tmp_path_factory.mktemp("out")), runs=1, scaling_runs=1,
                               accuracy_side=24, delta_e_samples=500, resolutions=((16, 16),))
    yield workload.Workload(plan, tmp_path_factory.mktemp("work"))
    patch.undo()


def row(work, name):
    rows = dict(methods.method_rows(work))
    method, record = measure.measure_row(work, name, rows[name])
    assert "error" not in record, record
    return method, record


def test_direct_float32_row_matches_the_reference(tiny_work):
    _, record = row(tiny_work, "direct float32")
    assert record["max_error_8bit"] < 0.1 and record["mean_delta_e2000"] < 0.01


def test_opencolorio_applies_the_same_lut_as_torchgrade(tiny_work):
    _, ours = row(tiny_work, rows.lut_name(33, "logc", "tetrahedral"))
    _, peer = row(tiny_work, "OpenColorIO 33³ logc tetrahedral")
    # The same lattice; they differ by where the output is interpolated (torchgrade: sRGB-encoded
    # entries, clip after the lookup; the .cube file: linear entries) and the .cube's 1D shaper.
    assert ours["mean_delta_e2000"] < 0.5 and peer["mean_delta_e2000"] < 0.5


def test_failing_row_records_its_error(tiny_work):
    def broken():
        raise RuntimeError("no compiler\nsecond line")

    _, record = measure.measure_row(tiny_work, "broken", broken)
    assert record == {"method": "broken", "error": "RuntimeError: no compiler"}


def test_report_and_plots(tiny_work, tmp_path):
    _, record = row(tiny_work, rows.lut_name(33, "logc", "tetrahedral"))
    records = [record, {"method": "broken", "error": "RuntimeError: x"}]
    assert "failed: RuntimeError: x" in report.markdown_table(records)
    measure.add_speed(records, {record["method"]: [2.0], measure.COPY: [1.0], measure.LIVE: [1.0], measure.LIVE64: [1.0]})
    report.plot_pareto(records, tmp_path / "pareto.png")
    points = measure.scaling(tiny_work)
    report.plot_scaling(points, tmp_path / "scaling.png")
    assert {p["path"] for p in points} == {"direct float32", rows.default_name(tiny_work.default_lut, "tetrahedral")}
    for name in ("pareto.png", "scaling.png"):
        assert 0 < (tmp_path / name).stat().st_size < 200_000


def test_timer_alternates_and_rotates_the_calls():
    order = []
    calls = {name: (lambda name=name: order.append(name)) for name in "ABC"}
    times = common.interleaved_ms(calls, runs=2, warmup=1)
    assert "".join(order) == "ABCBCACAB" and {name: len(ms) for name, ms in times.items()} == {"A": 2, "B": 2, "C": 2}


def test_ratios_are_medians_of_each_rounds_ratio():
    """Rounds where the machine slowed everything 3x: each round's ratio is 2, while the ratio of the medians is not."""
    times = {"row": [2.0, 6.0, 6.0, 2.0, 2.0], measure.COPY: [1.0, 3.0, 3.0, 1.0, 1.0], methods.PEER: [4.0, 4.0, 4.0, 4.0, 4.0],
             measure.LIVE: [1.0] * 5, measure.LIVE64: [1.0] * 5}
    records = [{"method": "row", "timed": "per-pixel stage"}, {"method": "not built", "error": "x"}]
    base = measure.add_speed(records, times)
    assert records[0]["ms"] == 2.0 and records[0]["ratio_to_copy"] == 2.0 and records[0]["ratio_to_opencolorio"] == 0.5
    assert base == {measure.COPY: 1.0, measure.LIVE: 1.0, measure.LIVE64: 1.0} and "ms" not in records[1]


def test_whole_look_check_flags_a_look_faster_than_its_parts():
    times = {measure.WHOLE_LOOK: [10.0, 12.0, 30.0], measure.PER_PIXEL: [8.0, 9.0, 20.0], measure.LIVE: [3.0, 3.0, 9.0]}
    check = measure.whole_look_check(times)
    assert check["whole_over_parts"] == pytest.approx(1.0) and check["whole_look_ms"] == 12.0  # rounds: 10/11, 12/12, 30/29
    assert "not to be trusted" in report.check_line(measure.whole_look_check({**times, measure.WHOLE_LOOK: [5.0, 5.0, 5.0]}))
    assert "not to be trusted" not in report.check_line({**check, "whole_over_parts": 1.1})
    assert measure.whole_look_check({measure.PER_PIXEL: [1.0]}) is None


def record_of(method, family, ms, p999, largest, shaper=None, timed="per-pixel stage", **more):
    megapixels = workload.FRAME[0] * workload.FRAME[1] / 1e6
    return {"method": method, "family": family, "timed": timed, "ms": ms, "ms_per_megapixel": ms / megapixels,
            "p999_error_8bit": p999, "max_error_8bit": largest, **({"shaper": shaper} if shaper else {}), **more}


def test_advice_follows_the_measured_numbers():
    default = "LUT 5³ lattice tetrahedral, default bake"
    records = [record_of("direct float32", "direct", 100.0, 0.0, 0.2), record_of("direct float16", "direct", 60.0, 0.1, 9.0),
               record_of("LUT 9³ linear tetrahedral", "lut", 5.0, 40.0, 150.0, shaper="linear"),
               record_of(default, "lut", 20.0, 6.0, 12.0, shaper="lattice", default_bake=True, lut_size=5,
                         interpolation="tetrahedral"),
               record_of("LUT 65³ logc tetrahedral", "lut", 25.0, 3.0, 40.0, shaper="logc", interpolation="tetrahedral")]
    training, serving, baking = report.advice(records, {measure.LIVE: 20.0})
    assert training.startswith("Training augmentation: direct float32") and "direct float16 takes 0.60×" in training
    assert serving.startswith("Serving: direct float16") and f"{default} takes 0.33×" in serving and "linear" not in serving
    assert baking.startswith("Baking a LUT: LUT 65³ logc tetrahedral") and "the default bake (lattice, 5³ tetrahedral): p99.9 6.00" in baking
    records[0]["max_error_8bit"] = 2.0  # float32 no longer within a code: float64 would be needed, and none was timed
    assert report.training_advice(records).startswith("Training augmentation: no PyTorch row")


def test_pareto_plot_offers_no_linear_shaper_lut():
    records = [record_of("LUT 33³ linear tetrahedral", "lut", 5.0, 40.0, 150.0, shaper="linear"),
               record_of("OpenColorIO 33³ linear tetrahedral", "opencolorio", 5.0, 40.0, 150.0, shaper="linear"),
               record_of("LUT 33³ logc_hdr tetrahedral", "lut", 6.0, 6.0, 12.0, shaper="logc_hdr"),
               record_of("direct float32, whole look", "direct", 9.0, 0.0, 0.2, timed="whole look")]
    assert [r["method"] for r in report.hdr_choices(records)] == ["LUT 33³ logc_hdr tetrahedral"]


def test_warnings_are_counted_once_per_message():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            warnings.warn("lattice too small", tg.lut.LUTAccuracyWarning, stacklevel=1)
        warnings.warn("other", UserWarning, stacklevel=1)
    assert report.warning_records(caught) == [{"category": "LUTAccuracyWarning", "message": "lattice too small", "count": 3},
                                              {"category": "UserWarning", "message": "other", "count": 1}]


def test_results_record_where_they_were_measured(tmp_path):
    out = tmp_path / "out"
    common.write_results(out, "tiny", {"rows": [1]}, ["| a |"], "cmd")
    record = json.loads((out / "tiny.json").read_text())
    env = record["environment"]
    assert record["rows"] == [1] and env["device"] == "cpu" and env["torch_threads"] == torch.get_num_threads()
    assert len(env["load_average"]) == 3 and env["cpu_count"] == os.cpu_count()
    assert env["versions"]["torch"] == torch.__version__ and env["versions"]["torchgrade"] == tg.__version__
    assert ("onnxruntime" in env["versions"]) == ("onnxruntime" in sys.modules)
    assert (out / "tiny.md").read_text().splitlines()[-1].startswith("Measured on cpu")
    assert not (common.RESULTS / "tiny.json").exists()


def test_compare_runs_lists_every_ratio_both_runs_measured_and_its_spread():
    from benchmarks import compare_runs

    first = {"rows": [{"method": "a", "ratio_to_copy": 4.0, "ratio_to_opencolorio": None}, {"method": "only here", "ratio_to_copy": 1.0}],
             "check": {"whole_over_parts": 1.1}}
    second = {"rows": [{"method": "a", "ratio_to_copy": 5.0, "ratio_to_opencolorio": 2.0}], "check": {"whole_over_parts": 1.0}}
    rows = compare_runs.ratio_rows(first, second)
    assert [(r["method"], r["ratio"]) for r in rows] == [("a", "× copy"), ("eager whole look", "/ (bloom + per-pixel)")]
    assert [r["spread"] for r in rows] == pytest.approx([0.25, 0.1])


RESULT_SCRIPTS = sorted(module for name, module in NAMES.items() if name != "cpu_paths")
"""Every benchmark but cpu_paths, which prints its figures (``--json FILE`` on request) and imports only torchgrade, so
that it runs under another checkout's ``PYTHONPATH``."""


def test_the_door_lists_every_benchmark_and_marks_the_quick_ones():
    listed = subprocess.run([sys.executable, "-m", "benchmarks", "--list"], cwd=common.ROOT, capture_output=True, text=True,
                            check=True).stdout.splitlines()
    assert sorted(line.split()[0] for line in listed) == sorted(NAMES)
    quick = {line.split()[0] for line in listed if line.endswith("(--quick)")}
    assert {"suite", "lut_cpu", "lut_lattices"} <= quick and "bloom" not in quick


def test_the_door_refuses_an_unknown_name_and_a_quick_form_a_benchmark_lacks(capsys):
    assert door(["nothing_here"]) == 2 and "no benchmark named 'nothing_here'" in capsys.readouterr().err
    assert door(["bloom", "--quick"]) == 2 and "bloom has no quick form" in capsys.readouterr().err


def test_no_benchmark_patches_the_import_path():
    patched = [path.name for path in (common.ROOT / "benchmarks").rglob("*.py") if "sys.path" in path.read_text()]
    assert patched == []


def test_every_committed_result_is_named_by_its_benchmark():
    """``NAME.md``/``.json``, ``NAME_*`` or the folder ``NAME/``, for a NAME the door runs."""
    def owner(entry: Path) -> bool:
        stem = entry.name if entry.is_dir() else entry.name.split(".")[0]
        return any(stem == name or stem.startswith(f"{name}_") for name in NAMES)

    assert [entry.name for entry in sorted(common.RESULTS.iterdir()) if not owner(entry)] == []


@pytest.mark.parametrize("script", RESULT_SCRIPTS)
def test_every_benchmark_takes_out_and_defaults_away_from_the_committed_results(script, capsys):
    module = importlib.import_module(f"benchmarks.{script}")
    with pytest.raises(SystemExit) as exit_info:
        module.main(["--help"])
    assert exit_info.value.code == 0
    usage = " ".join(capsys.readouterr().out.split())
    assert "--out OUT" in usage and "default benchmarks/out" in usage
    assert ("--quick" in usage) == bool(getattr(module, "QUICK", None))


def test_a_tiny_run_writes_to_out_only_prints_a_short_table_and_collects_its_warnings(tmp_path, monkeypatch, capsys):
    for name, value in {"FRAME": (24, 32), "DEMO_SIZE": (24, 32), "BATCHES": (1,), "BATCH_SIDE": 8,
                        "RESOLUTIONS": ((8, 8),) * 3, "QUICK_RUNS": 2}.items():
        monkeypatch.setattr(workload, name, value)
    monkeypatch.setattr(workload, "accuracy_scenes", lambda plan: {"demo scene": tg.scene.demo_scene(16, 24)})
    kept = ("direct float32", "direct float32, whole look", rows.lut_name(33, "logc", "tetrahedral"), methods.PEER)
    every_row = methods.method_rows
    monkeypatch.setattr(measure, "method_rows", lambda work: [(n, b) for n, b in every_row(work) if n in kept])
    before = sorted(common.RESULTS.rglob("*"))
    assert door(["suite", "--quick", "--out", str(tmp_path)]) == 0
    assert sorted(common.RESULTS.rglob("*")) == before
    assert {p.name for p in tmp_path.iterdir()} == {"results.json", "results.md", "pareto.png", "scaling.png"}
    written = json.loads((tmp_path / "results.json").read_text())
    assert written["environment"]["device"] == "cpu" and written["runs"] == 2 and written["command"].endswith(f"--out {tmp_path}")
    assert set(written["rounds_ms"]) == {*kept, measure.COPY, measure.LIVE}
    assert all(len(ms) == 2 for ms in written["rounds_ms"].values())
    assert {w["category"] for w in written["warnings"]} == {"LUTAccuracyWarning"}  # the 33³ bakes miss the look
    assert [line.split(":")[0] for line in written["advice"]] == ["Training augmentation", "Serving", "Baking a LUT"]
    assert written["check"]["whole_over_parts"] > 0 and written["cpu_s"] > 0 and "modified" in written
    printed = capsys.readouterr().out.splitlines()
    header = next(at for at, line in enumerate(printed) if line.split() == ["method", "ms/MP", "×OCIO", "p99.9", "max", "ΔE"])
    assert [line.split("  ")[0] for line in printed[header + 1:header + len(kept) + 1]] == list(kept)
    assert "{" not in "".join(printed)


@pytest.mark.parametrize("interpolation", ["trilinear", "tetrahedral"])
def test_lut_floor_interpolation_matrix_is_the_library_lookup(interpolation):
    """interpolation_matrix raises unless its weights reproduce the library's kernel; rows sum to 1."""
    coords = torch.rand(3, 500, dtype=torch.float64, generator=torch.Generator().manual_seed(1)) * 4.0
    special = [(0.0, 0.0, 0.0), (4.0, 4.0, 4.0), (2.0, 2.0, 2.0), (4.0, 1.5, 2.25), (1.5, 1.5, 0.25), (0.25, 3.5, 3.5), (2.5, 0.5, 2.5)]
    coords[:, : len(special)] = torch.tensor(special, dtype=torch.float64).t()  # lattice points, top faces, two-way ties
    matrix = lut_floor.interpolation_matrix(coords, 5, interpolation)
    assert matrix.shape == (500, 125)
    assert abs(matrix.sum(axis=1) - 1.0).max() < 1e-12


def test_lut_floor_kernel_check_catches_wrong_weights(monkeypatch):
    right = lut_floor.vertex_weights

    def swapped(coords, size, interpolation):
        index, weights = right(coords, size, interpolation)
        return index, weights[:, ::-1].copy()

    monkeypatch.setattr(lut_floor, "vertex_weights", swapped)
    with pytest.raises(AssertionError, match="differ from the library"):
        lut_floor.interpolation_matrix(torch.rand(3, 50, dtype=torch.float64) * 4.0, 5, "tetrahedral")


def test_lut_floor_entry_interval_opens_where_the_display_clips():
    low, high = lut_floor.entry_interval(torch.tensor([128.0, 2.0, 254.0]).numpy(), 4.0, "srgb")
    assert low[0] == pytest.approx(124 / 255) and high[0] == pytest.approx(132 / 255)
    assert low[1] == -float("inf") and high[2] == float("inf")  # below 0 or above 1 the clip shows black or white
    low, high = lut_floor.entry_interval(torch.tensor([128.0]).numpy(), 1.0, "linear")
    assert float(metrics.srgb_codes(torch.tensor(low).reshape(1, 1, 1, 1).expand(1, 3, 1, 1))[0, 0]) == pytest.approx(127.0)
    assert float(metrics.srgb_codes(torch.tensor(high).reshape(1, 1, 1, 1).expand(1, 3, 1, 1))[0, 0]) == pytest.approx(129.0)


def test_lut_floor_finds_a_table_when_one_exists_and_measures_when_none_can():
    """Pixels read from a known table are met exactly; two pixels at one lattice point 10 codes apart miss a bar
    of 4 by exactly 1 code each way, and meet a bar of 5.5."""
    coords = torch.rand(3, 200, dtype=torch.float64, generator=torch.Generator().manual_seed(2)) * 2.0
    matrix = lut_floor.interpolation_matrix(coords, 3, "tetrahedral")
    table = torch.rand(27, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(3)).numpy() * 0.8 + 0.1
    codes = (255.0 * (matrix @ table)).T  # sRGB-encoded entries display as 255 * entry
    assert lut_floor.table_exists(lut_floor.channel_violations(matrix, codes, 0.01, "srgb")) is True
    twin = torch.ones(3, 2, dtype=torch.float64)
    twin_matrix = lut_floor.interpolation_matrix(twin, 3, "trilinear")
    apart = torch.tensor([[100.0, 110.0]] * 3).numpy()
    violations = lut_floor.channel_violations(twin_matrix, apart, 4.0, "srgb")
    assert violations == pytest.approx([1 / 255] * 3) and lut_floor.table_exists(violations) is False
    assert lut_floor.table_exists(lut_floor.channel_violations(twin_matrix, apart, 5.5, "linear")) is True


def test_lut_floor_lowest_max_error_and_l1_share_on_pixels_with_a_known_answer():
    """Pixels at one lattice point read one entry: the best entry sits midway between their codes, and the L1 table
    puts it where only the outlier stays more than 1 code off."""
    point = torch.ones(3, 2, dtype=torch.float64)
    matrix = lut_floor.interpolation_matrix(point, 3, "trilinear")
    apart = np.array([[100.0, 110.0]] * 3)
    lower, upper = lut_floor.lowest_max_error(matrix, apart)
    assert lower <= 5.0 <= upper and upper - lower <= lut_floor.FLOOR_RESOLUTION
    four = lut_floor.interpolation_matrix(torch.ones(3, 4, dtype=torch.float64), 3, "tetrahedral")
    assert lut_floor.l1_table_share_over(four, np.array([[100.0, 100.0, 100.0, 103.0]] * 3)) == pytest.approx(0.25)


def test_lut_floor_lowest_max_error_counts_the_display_clip():
    """Codes 254, 200 and 0 at lattice coordinates 0, 0.5 and 1 along red: entries 400/255 and 0 display 255, 200 and 0,
    a max error of 1 (an entry above 1 shows white); bringing the first pixel closer than 1 code costs the last one
    over 145 codes. So the floor is exactly 1 code."""
    coords = torch.tensor([[0.0, 0.5, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], dtype=torch.float64)
    matrix = lut_floor.interpolation_matrix(coords, 3, "trilinear")
    lower, upper = lut_floor.lowest_max_error(matrix, np.array([[254.0, 200.0, 0.0]] * 3))
    assert lower <= 1.0 <= upper + 1e-6 and upper - lower <= lut_floor.FLOOR_RESOLUTION


def test_lut_floor_retries_with_interior_point_on_numerical_trouble(monkeypatch):
    methods = []
    real = lut_floor.linprog

    def troubled_simplex(*args, method, **kwargs):
        methods.append(method)
        result = real(*args, method=method, **kwargs)
        if method == "highs":
            result.status = lut_floor.NUMERICAL_DIFFICULTIES
        return result

    monkeypatch.setattr(lut_floor, "linprog", troubled_simplex)
    matrix = lut_floor.interpolation_matrix(torch.ones(3, 2, dtype=torch.float64), 3, "trilinear")
    assert lut_floor.smallest_violation(matrix, np.array([100.0, 110.0]), 4.0, "srgb") == pytest.approx(1 / 255)
    assert methods == ["highs", "highs-ipm"]


def test_no_33_logc_table_on_the_scene_lattice_keeps_every_desk_pixel_within_4_codes():
    """The claim of benchmarks/results/lut_floor.md that makes the LUT accuracy bar unreachable on Desk: even with the
    lattice covering every pixel (black to the scene's largest value), no tetrahedral table with sRGB entries keeps
    every blue value within 4 codes."""
    image, _, direct = lut_floor.measured_scene("Desk", False)
    low, high = lut_floor.lattice_domain(image, "scene")
    points = image.double().reshape(3, -1)
    assert float(linear_to_logc(points.max())) == pytest.approx(high)  # the lattice's top is the brightest value
    coords = lut_floor.lattice_unit(points, "logc", low, high) * (lut_floor.SIZE - 1)
    matrix = lut_floor.interpolation_matrix(coords, lut_floor.SIZE, "tetrahedral")
    violation = lut_floor.smallest_violation(matrix, direct[2], lut_floor.MAX_BAR, "srgb")
    assert 255.0 * violation > 0.3  # in codes: far beyond HiGHS tolerances (1e-7 table units), so the verdict does not hang on them


def test_committed_scene_fitted_tables_miss_every_photograph_by_less_than_any_logc_table_can():
    """The claims tests/lut/test_lut_report.py checks on CandleGlass, on bench_lut_fit.py's committed results for all
    three photographs: the scene-fitted 33³ table with fitted entries below the LogC floor on the seen pixels, below the
    default table on the unseen ones, and on Desk's pixels above the logc lattice's top under a quarter of logc's error."""
    results = json.loads((common.RESULTS / "lut_fit.json").read_text())
    rows = {(row["image"], row["lattice"], row["entries"]): row for row in results["rows"]}
    for image, floor in results["logc_floor"].items():
        fitted, default = rows[image, "fitted to the scene", "fitted"], rows[image, "LogC to 65504 (default)", "sampled"]
        assert fitted["seen"]["max"] < floor, image
        assert fitted["unseen"]["p99_9"] < default["unseen"]["p99_9"], image
    above = {lattice: rows["Desk", lattice, entries]["seen_above_logc_top"] for lattice, entries in
             (("fitted to the scene", "fitted"), ("LogC to 58.86", "sampled"))}
    assert above["LogC to 58.86"]["pixels"] > 1000
    assert above["fitted to the scene"]["max"] < above["LogC to 58.86"]["max"] / 4, above


def test_every_operator_pattern_of_the_onnx_cost_benchmark_builds_and_keeps_the_strip():
    pytest.importorskip("onnxruntime")
    from benchmarks import bench_onnx_ops

    strip = np.random.default_rng(0).random(bench_onnx_ops.STRIP, dtype=np.float32)
    for name, step in bench_onnx_ops.PATTERNS.items():
        out = bench_onnx_ops.chain_session(step).run(None, {"x": strip})[0]
        assert out.shape == bench_onnx_ops.STRIP and np.isfinite(out).all(), name


def test_gpu_proxy_charges_a_frame_pass_its_copy_time_and_a_small_launch_the_launch_floor():
    from benchmarks import gpu_proxy
    from torchgrade.testing.dispatch import DispatchCount

    frame = torch.empty(1, 3, 2160, 3840, device="meta")
    with DispatchCount(frame=frame) as count:
        frame * 2.0  # reads and writes the frame once: one frame pass
        frame[..., :1, :1] + 1.0  # a view (no launch), then a launch that moves 24 bytes
    assert count.launches == 2 and count.frame_passes == pytest.approx(1.0, abs=1e-6)
    assert gpu_proxy.predicted_ms(count) == pytest.approx(gpu_proxy.PASS_COST * gpu_proxy.COPY_4K_MS + gpu_proxy.LAUNCH_MS, rel=1e-6)


def test_the_dispatch_count_charges_an_out_result_once_and_an_allocation_nothing():
    from torchgrade.testing.dispatch import DispatchCount

    frame = torch.empty(1, 3, 2160, 3840, device="meta")
    with DispatchCount(frame=frame) as count:
        result = torch.empty_like(frame)  # the caching allocator's work: no kernel
        torch.floor(frame, out=result)  # reads the frame, writes the result: one pass
        result.add_(frame)  # reads both, writes one: one and a half
    assert count.launches == 2 and count.frame_passes == pytest.approx(2.5, abs=1e-6)


def test_the_dispatch_count_tells_unvectorised_launches_row_gathers_and_host_arithmetic_apart():
    from torchgrade.runtime import constant, scalar
    from torchgrade.testing.dispatch import DispatchCount

    frame = torch.empty(1, 3, 512, 512, device="meta")
    table = torch.empty(363, 8, device="meta")
    index = torch.zeros(512 * 512, dtype=torch.long, device="meta")
    with DispatchCount(frame=frame) as count:
        frame * constant(2.0, frame)  # a 0-d operand on the device: broadcast, unvectorised on CUDA
        frame * scalar(2.0, frame)  # a 0-d CPU operand: an argument of a vectorised kernel
        frame[:, :1] * frame[:, 1:2]  # two planes, contiguous: vectorised
        table[index]  # rows of 32 bytes: CUDA's gather of a block of threads an index
        table[:, :6][index]  # rows of 24 bytes: not that gather
        scalar(2.0, frame) * scalar(3.0, frame)  # arithmetic in the host's memory: no launch
    assert (count.launches, count.unvectorised, count.row_gathers) == (5, 1, 1)


def test_the_gpu_benchmark_writes_its_results_without_cuda(tmp_path):
    from benchmarks import bench_gpu

    assert bench_gpu.main(["--sections", "kernels,forms", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "gpu.json").read_text())
    assert report["skipped"] == ["kernels (no CUDA)", "forms (no CUDA)"] and not report["errors"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gpu.json", "gpu.md"]  # no temporary file left


def test_the_serving_benchmark_exits_0_through_the_door_and_writes_its_table(tmp_path, monkeypatch, capsys):
    """``python -m benchmarks serving`` exits with what its ``main`` returns: it returned its results, which
    ``sys.exit`` printed and exited 1 with. The server and its clients stand in here (the serving tests run them)."""
    from benchmarks import bench_serving

    run = {"requests": 16, "concurrency": 16, "statuses": {"200": 16}, "latency_ms_p50": 1.0, "latency_ms_p99": 2.0,
           "latency_ms_max": 3.0, "slow_answers": {}, "server": {"peak_rss_mib": 900.0,
                                                                  "memory": {"held_peak_mib": 10.0, "waited": 0}}}

    class Served:
        url = "http://127.0.0.1:1"

        def __init__(self, model, flags):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *_):
            pass

        def client(self, flags, out):
            return run

    monkeypatch.setattr(bench_serving, "Server", Served)
    monkeypatch.setattr(bench_serving, "_get_json", lambda url: {"idle_mib": 500.0, "costs": {}})
    monkeypatch.setattr(tg.onnx, "export", lambda look, path, **options: path)
    assert door(["serving", "--quick", "--out", str(tmp_path)]) == 0
    assert "| real frames | 16 | 16 |" in (tmp_path / "serving.md").read_text()
    assert "{'command'" not in capsys.readouterr().err


def test_the_look_floor_times_every_case_against_the_copy_in_the_same_rounds_and_counts_the_passes(tmp_path, monkeypatch):
    from benchmarks import look_floor

    monkeypatch.setattr(look_floor, "PHOTOGRAPHS", ("Carrots",))
    threads = torch.get_num_threads()
    before = sorted(common.RESULTS.rglob("*"))
    assert door(["look_floor", "--quick", "--out", str(tmp_path)]) == 0
    assert sorted(common.RESULTS.rglob("*")) == before and torch.get_num_threads() == threads
    report = json.loads((tmp_path / "look_floor.json").read_text())
    assert report["command"].endswith(f"look_floor --quick --out {tmp_path}") and report["commit"] and report["threads"] == 2
    rows, rounds = report["timing"]["rows"], report["timing"]["rounds_ms"]
    assert set(rows) == {look_floor.COPY, "frame copy into a frame made once", look_floor.EAGER, look_floor.EXPORTED,
                         *look_floor.STAGES.values()}
    assert rows[look_floor.COPY]["over_copy"] == 1.0 and all(len(ms) == look_floor.QUICK_ROUNDS for ms in rounds.values())
    counts = report["eager_counts"]
    stages = [counts[name]["operations"] for name in look_floor.STAGES.values()]
    assert max(stages) < counts[look_floor.EAGER]["operations"] <= sum(stages)  # the stages, the frame sanitized once
    assert counts[look_floor.STAGES["tonemap"]]["frames_written"] >= 1.0  # its output at least
    nodes = report["onnx"]
    assert nodes["nodes"] == sum(nodes["operators"].values()) > nodes["main_graph_nodes"]  # the Scan's body counted
    assert set(report["metering"]["Carrots"]) == set(tg.exposure.METERING_MASKS)
    assert report["metering"]["Carrots"]["spot"]["4x4 blocks"] > report["metering"]["Carrots"]["spot"]["2x2 blocks"] > 0


def test_the_code_inductor_generates_is_read_from_its_log_with_sizes_at_the_frame(tmp_path, monkeypatch):
    """A compiled tone map of a frame with symbolic sides: one kernel, one buffer of a plane or more (its output, a
    frame), read from the ``output_code`` log; torch's logging is left as it was."""
    from benchmarks import look_floor

    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path))  # the code is generated, not read from a cache
    handlers = list(logging.getLogger("torch._inductor").handlers)
    with look_floor.inductor_output_code() as sources, torch.no_grad():
        tg.compile(tg.ToneMap("reinhard"), verbose=False)(torch.rand(1, 3, 24, 40))
    assert logging.getLogger("torch._inductor").handlers == handlers
    counts = [look_floor.code_counts(source, 24 * 40) for source in sources]
    assert counts == [{"kernels": 1, "loop_nests": counts[0]["loop_nests"], "frame_buffers": 1, "frames_written": 1.0}]
    assert counts[0]["loop_nests"] >= 1
