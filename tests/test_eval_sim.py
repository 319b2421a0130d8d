"""`monitor eval-sim`: scoring rules on hand-made detections, then small runs via the CLI.

The CLI runs use far fewer runs than --quick so the suite stays fast; they check structure
and invariants that hold by construction (rates in 0..1, confusion rows summing to the run
counts, delays >= 0), plus one empirical fact with a wide margin: an abrupt spool_wear at
full severity is detected.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from monitor.cli import main
from monitor.detection.alarm import State
from monitor.detection.offline import Detection
from monitor.errors import ConfigError
from monitor.evaluation.report import ISOLATION_LABELS
from monitor.evaluation.sim_eval import (
    FAULT_SEED_BASE,
    NORMAL_SEED_BASE,
    EvalConfig,
    RunSpec,
    fault_plan,
    fault_seed,
    normal_plan,
    planned_seeds,
    score_run,
)
from monitor.signals import FAULT_NAMES


def _detection(
    states: list[tuple[float, float, State]], first_label: str | None, events: list[dict]
) -> Detection:
    """A 60 s detection at 100 Hz whose state is set per (start_s, stop_s, state) span."""
    t = np.arange(6001) * 0.01
    state = np.full(t.size, int(State.NORMAL), dtype=np.int8)
    for start, stop, s in states:
        state[(t >= start - 1e-9) & (t < stop - 1e-9)] = int(s)
    nan = np.full(t.size, np.nan)
    alarmed = bool(np.any(state == int(State.FAULT)))
    first = float(t[np.argmax(state == int(State.FAULT))]) if alarmed else None
    summary = {
        "alarm": alarmed,
        "first_alarm_t": first,
        "fault": first_label,
        "sensor_fault": False,
        "max_J": 3.0,
        "threshold": 2.0,
    }
    return Detection(t, nan, nan, nan, state, events, summary)


FAULT = RunSpec(
    seed=1, duration_s=60.0, fault="spool_wear", severity=1.0, onset="abrupt", onset_s=30.0
)


def test_score_detected_after_onset_uses_summary_label() -> None:
    det = _detection([(33.5, 45.0, State.FAULT)], "spool_wear", [])
    r = score_run(det, FAULT)
    assert r["detected"] and r["delay_s"] == pytest.approx(3.5)
    assert r["isolated"] == "spool_wear" and r["pre_onset_alarms"] == 0
    assert r["max_J_over_eps0"] == pytest.approx(1.5)


def test_score_pre_onset_alarm_is_a_false_alarm_not_a_detection() -> None:
    events = [
        {"t": 10.0, "state": "fault", "fault": "unknown"},
        {"t": 40.0, "state": "fault", "fault": "piston_wear"},
    ]
    det = _detection([(10.0, 20.0, State.FAULT), (40.0, 50.0, State.FAULT)], "unknown", events)
    r = score_run(det, FAULT)
    assert r["pre_onset_alarms"] == 1
    # The summary belongs to the false alarm; the post-onset episode's own label is used.
    assert r["detected"] and r["delay_s"] == pytest.approx(10.0)
    assert r["isolated"] == "piston_wear"


def test_score_alarm_only_before_onset_is_missed() -> None:
    det = _detection([(10.0, 35.0, State.FAULT)], "unknown", [])
    r = score_run(det, FAULT)
    assert r["pre_onset_alarms"] == 1
    assert not r["detected"] and r["delay_s"] is None and r["isolated"] == "none"


def test_score_normal_counts_episodes() -> None:
    det = _detection([(5.0, 8.0, State.FAULT), (20.0, 21.0, State.FAULT)], "unknown", [])
    r = score_run(det, RunSpec(seed=2, duration_s=60.0))
    assert r["alarm_episodes"] == 2 and r["alarm_times_s"] == [5.0, 20.0]


def test_plan_seeds_unique_and_disjoint_from_training() -> None:
    cfg = EvalConfig(runs=10, normal_hours=10.0)
    fp, nplan = fault_plan(cfg), normal_plan(cfg)
    assert len(fp) == 3 * 10 * 2 * 10
    assert len({r.seed for r in fp + nplan}) == len(fp) + len(nplan)
    assert sum(r.duration_s for r in nplan) == pytest.approx(36000.0)
    seeds = planned_seeds(cfg)
    # Training seeds (1-8) and the isolation signatures' (70000-73000) are far below.
    assert min(seeds) >= NORMAL_SEED_BASE and NORMAL_SEED_BASE > 73_000
    assert max(r.seed for r in nplan) < FAULT_SEED_BASE
    assert fault_seed("spool_wear", 1.0, "gradual", 99) < FAULT_SEED_BASE + 300_000


def _check_invariants(result: dict[str, Any]) -> None:
    cfg = result["config"]
    per_cell = cfg["runs"]
    for m in result["models"].values():
        assert m["eps0"] > 0
        fa = m["false_alarms_normal"]
        assert fa["alarm_episodes"] >= fa["runs_with_alarm"] >= 0
        assert fa["hours"] == pytest.approx(cfg["normal_hours"], rel=1e-3)
        for row in m["per_severity"]:
            for onset in (*cfg["onsets"], "all"):
                c = row[onset]
                n = per_cell * (len(cfg["onsets"]) if onset == "all" else 1)
                assert c["runs"] == n and 0 <= c["detected"] <= n
                assert 0.0 <= c["detection_rate"] <= 1.0
                if c["detected"]:
                    assert 0.0 <= c["isolation_accuracy"] <= 1.0
                    assert 0.0 <= c["median_delay_s"] <= c["max_delay_s"]
                else:
                    assert c["median_delay_s"] is None and c["isolation_accuracy"] is None
        conf = m["confusion"]
        assert conf["columns"] == list(ISOLATION_LABELS)
        n_fault = per_cell * len(cfg["severities"]) * len(cfg["onsets"])
        for fault in FAULT_NAMES:
            row = conf["all"][fault]
            assert sum(row.values()) == n_fault
            detected = sum(r["all"]["detected"] for r in m["per_severity"] if r["fault"] == fault)
            assert n_fault - row["none"] == detected
        for r in m["runs"]["fault"]:
            assert (r["delay_s"] is None) == (not r["detected"])
            assert r["delay_s"] is None or r["delay_s"] >= 0.0


def test_cli_trains_paper_preset(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A preset trained afresh, its fault signatures from one simulated run per fault and
    severity (--isolation-runs 1; the default 8 took most of this test's time)."""
    from monitor.training.train import ISOLATION_SEVERITIES

    out, md = tmp_path / "eval.json", tmp_path / "eval.md"
    code = main(
        [
            "eval-sim",
            "--presets",
            "paper",
            "--train-seeds",
            "1-3",
            "--train-duration",
            "90",
            "--isolation-runs",
            "1",
            "--severities",
            "0.6",
            "--runs",
            "1",
            "--onsets",
            "abrupt",
            "--normal-hours",
            "0.02",
            "--json",
            str(out),
            "--markdown",
            str(md),
        ]
    )
    assert code == 0
    result = json.loads(out.read_text())
    assert result["models"]["paper"]["outputs"] == ["QP"]
    assert result["plan"]["train_seeds"] == [1, 2, 3]
    assert result["plan"]["train_isolation_runs"] == 1
    assert "--isolation-runs 1 " in result["rerun"]
    runs = len(FAULT_NAMES) * len(ISOLATION_SEVERITIES)  # one run per fault and severity
    assert f"learning fault signatures from {runs} simulated runs" in capsys.readouterr().err
    _check_invariants(result)
    text = md.read_text()
    assert "### paper" in text and "Table 1, all models" in text


@pytest.mark.parametrize(
    "argv",
    [
        ["--train-seeds", "100000-100002"],  # overlaps the normal test seeds
        ["--severities", "0,1"],
        ["--severities", "x"],
        ["--runs", "0"],
        ["--isolation-runs", "0"],
        ["--onsets", "sudden"],
        ["--presets", "nope"],
        ["--onset", "5"],
        ["--model", "/nonexistent/model.npz"],
    ],
)
def test_cli_bad_arguments_exit_2(tmp_path: Path, argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc_info:
        raise SystemExit(main(["eval-sim", "--json", str(tmp_path / "x.json"), *argv]))
    assert exc_info.value.code == 2


def test_cli_json_folder_missing(tmp_path: Path) -> None:
    assert main(["eval-sim", "--model", "shipped", "--json", str(tmp_path / "no" / "x.json")]) == 2


def test_cli_shipped_model_small_set_and_dask_workers_give_the_one_process_rows(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """The shipped model on a small set (each fault at full severity, both onsets, one run
    each): its invariants and the markdown table; then --workers 2 (a Dask LocalCluster)
    scores the same runs to the same rows as that one-process loop; only the timings
    differ.  (One one-process run for both: they were two runs of the same model.)"""
    common = [
        "eval-sim",
        "--model",
        "shipped",
        "--severities",
        "1.0",
        "--runs",
        "1",
        "--normal-hours",
        "0.1",
    ]
    one, two = tmp_path / "one.json", tmp_path / "two.json"
    assert main([*common, "--json", str(one)]) == 0
    result = json.loads(one.read_text())
    assert list(result["models"]) == ["shipped"]
    assert result["plan"]["fault_runs"] == 6
    _check_invariants(result)
    m = result["models"]["shipped"]
    wear = next(r for r in m["per_severity"] if r["fault"] == "spool_wear")
    # Empirical (full evaluation): severity-1.0 spool wear peaks J far above eps0.
    assert wear["abrupt"]["detected"] == 1
    md = capsys.readouterr().out
    assert "| spool_wear | 1 |" in md and "Isolation confusion" in md
    assert main([*common, "--workers", "2", "--json", str(two)]) == 0
    a, b = (json.loads(p.read_text())["models"]["shipped"]["runs"] for p in (one, two))
    assert a == b
    assert len(a["fault"]) == 6 and len(a["normal"]) == 2


def test_seed_sets_are_disjoint() -> None:
    dev, blind = (
        EvalConfig(runs=10, normal_hours=10.0),
        EvalConfig(runs=10, normal_hours=10.0, seed_set=3),
    )
    assert not planned_seeds(dev) & planned_seeds(blind)
    assert len(planned_seeds(blind)) == len(planned_seeds(dev))
    assert min(planned_seeds(blind)) == NORMAL_SEED_BASE + 30_000_000


def test_the_largest_seed_set_keeps_every_seed_below_2_to_the_32() -> None:
    from monitor.evaluation.plan import MAX_SEED_SET

    top = EvalConfig(runs=100, normal_hours=100.0, seed_set=MAX_SEED_SET)
    assert max(planned_seeds(top)) < 2**32
    assert EvalConfig(seed_set=266).seed_set == 266  # a set drawn above the old cap of 200
    with pytest.raises(ConfigError):
        EvalConfig(seed_set=MAX_SEED_SET + 1)
