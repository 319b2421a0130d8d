"""`monitor fleet bench`: every way judges the same frames, side by side with `monitor detect`."""

from __future__ import annotations

import re
import shutil
import statistics

import pytest

from monitor.cli import main
from monitor.config.settings import load_config
from monitor.fleet.bench import bench_fleet
from monitor.fleet.simulate import FleetPlan, simulate_fleet

FRAME = re.compile(r"^\(\d+\.\d+\) \w+ [0-9A-F]+#[0-9A-F]*$")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """One machine, two 30 s logs, the shipped model as its commissioned one."""
    where = tmp_path_factory.mktemp("bench")
    fleet = where / "fleet"
    plan = FleetPlan(machines=1, days=2, seed=11, log_s=30.0, commissioning_s=60.0)
    simulate_fleet(fleet, plan, say=lambda _m: None)
    results = where / "results"
    (results / "models").mkdir(parents=True)
    shutil.copy(load_config(None).model, results / "models" / "M01.model.npz")
    return fleet, results


def test_each_way_judges_every_frame_and_is_set_beside_detect_per_worker(fleet):
    root, results = fleet
    out = bench_fleet(root, results, workers=(1,), repeats=2, dask_default=True)
    logs = sorted((root / "M01" / "logs").glob("*.log"))
    frames = sum(sum(1 for line in p.open() if FRAME.match(line.strip())) for p in logs)
    assert out["logs"] == len(logs) == 2
    assert out["frames"] == frames
    assert list(out["runs"]) == ["detect", "one_process", "workers_1", "workers_1_dask_default"]
    detect_rate = frames / statistics.median(out["runs"]["detect"]["s"])
    for r in out["runs"].values():
        assert len(r["s"]) == 2
        assert r["median_s"] == pytest.approx(statistics.median(r["s"]), rel=1e-9)
        per_worker = frames / r["median_s"] / r["workers"]
        assert r["frames_per_s_per_worker"] == pytest.approx(per_worker)
        assert r["vs_detect_per_worker"] == pytest.approx(per_worker / detect_rate, rel=1e-3)
        assert len(r["cpu_s"]) == 2 and min(r["cpu_s"]) > 0
        assert r["frames_per_cpu_s"] == pytest.approx(frames / statistics.median(r["cpu_s"]), 1e-3)
        detect_cpu = out["runs"]["detect"]["frames_per_cpu_s"]
        assert r["cpu_vs_detect"] == pytest.approx(r["frames_per_cpu_s"] / detect_cpu)
    assert out["runs"]["detect"]["vs_detect_per_worker"] == 1.0
    # Peak memory is a worker's own (a process judging logs: numpy and numba loaded, > 50 MB)
    assert out["runs"]["detect"]["worker_peak_rss_mb"] is None
    assert out["runs"]["workers_1"]["worker_peak_rss_mb"] > 50
    after = out["runs"]["workers_1"]["worker_rss_after_mb"]
    assert 50 < after <= out["runs"]["workers_1"]["worker_peak_rss_mb"]
    assert out["process_peak_rss_mb"] > 50
    assert len(out["load_average"]["start"]) == 3


def test_results_without_models_or_bad_repeats_are_one_line(fleet, tmp_path, capsys):
    root, _results = fleet
    assert main(["fleet", "bench", str(root), "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no model for any machine" in err[0]
    assert main(["fleet", "bench", str(root), "--results", str(tmp_path), "--repeats", "0"]) == 2
    assert "--repeats 0: at least 1" in capsys.readouterr().err
