"""`monitor eval-sim --machine excavator4`: the plan's seeds, the scoring of a fault run's
loops together, and a short run whose per-loop rows are recounted independently: each run
simulated again by `monitor simulate --machine excavator4` to a CSV, each loop judged by
`monitor detect --loop` from that file, and the entries into the fault state counted in its
event lines."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from monitor.cli import main
from monitor.errors import ConfigError
from monitor.evaluation.machine_eval import machine_row
from monitor.evaluation.machine_plan import (
    DEV_SEEDS,
    KNOWN_MACHINE_FAULTS,
    MachinePlan,
    all_runs,
    fault_runs,
    normal_runs,
)
from monitor.evaluation.machine_report import fault_cell
from monitor.evaluation.sim_eval import RunSpec
from monitor.resources import resource_path

LOOPS = ("boom", "stick", "bucket", "swing")


def test_plan_seeds_distinct_and_above_the_development_seeds() -> None:
    plan = MachinePlan(
        faults=KNOWN_MACHINE_FAULTS,
        severities=(0.1, 0.3, 1.0),
        runs=99,
        normal_hours=50,
        onsets=("abrupt", "gradual"),
    )
    seeds = [r.seed for r in all_runs(plan)]
    assert len(seeds) == len(set(seeds))
    assert min(seeds) > int(DEV_SEEDS.partition("-")[2])
    top = MachinePlan(
        seed_set=429, faults=KNOWN_MACHINE_FAULTS, runs=99, onsets=("abrupt", "gradual")
    )
    assert max(r.seed for r in all_runs(top)) < 2**32  # numpy's seed range
    shifted = MachinePlan(seed_set=1, normal_hours=1)
    assert {r.seed for r in all_runs(shifted)}.isdisjoint(
        r.seed for r in all_runs(MachinePlan(normal_hours=1))
    )
    # 1 h of normal operation: six 600 s pieces; a fault plan: faults x severities x runs.
    assert [r.duration_s for r in normal_runs(MachinePlan(normal_hours=1))] == [600.0] * 6
    assert len(fault_runs(MachinePlan(runs=2))) == 11 * 3 * 2


@pytest.mark.parametrize(
    "kw",
    [
        {"faults": ("stick.motor_leakage",)},
        {"faults": ("spool_wear",)},
        {"onset_s": 20.0},
        {"severities": (0.0,)},
        {"duration_s": 150.0},
        {"seed_set": 430},
    ],
)
def test_plan_refuses(kw: dict[str, Any]) -> None:
    with pytest.raises(ConfigError):
        MachinePlan(**kw)


def _loop(delay: float | None, pre: int = 0) -> dict[str, Any]:
    return {
        "detected": delay is not None,
        "delay_s": delay,
        "pre_onset_alarms": pre,
        "max_level": 1.5,
    }


def test_machine_row_names_the_first_loop_and_counts_neighbours() -> None:
    spec = RunSpec(1, 600.0, "stick.spool_wear", 0.5, "abrupt", 120.0)
    loops = {
        "boom": _loop(30.0),
        "stick": _loop(12.0, pre=1),
        "bucket": _loop(None),
        "swing": _loop(None),
    }
    row = machine_row(spec, loops)
    assert (row["detected"], row["delay_s"], row["named"]) == (True, 12.0, "stick")
    assert row["right_loop"] and row["neighbours"] == ["boom"]
    late = machine_row(spec, {**loops, "stick": _loop(40.0)})
    assert late["detected"] and late["named"] == "boom" and not late["right_loop"]
    missed = machine_row(spec, {**loops, "stick": _loop(None)})
    assert not missed["detected"] and missed["delay_s"] is None
    # The pump is no loop's: any loop's alarm detects it, and every alarm is a neighbour's.
    pump = machine_row(RunSpec(2, 600.0, "pump.pump_wear", 0.5, "abrupt", 120.0), loops)
    assert pump["detected"] and pump["delay_s"] == 12.0 and not pump["right_loop"]
    assert pump["neighbours"] == ["boom", "stick"]
    # The pump's rule alarmed: the pump is named, and the loops that alarmed after its
    # window began are explained by it, not neighbours' findings.
    spec_p = RunSpec(2, 600.0, "pump.pump_wear", 0.5, "abrupt", 120.0)
    pump_row = {**_loop(20.0), "max_level": 2.0, "window_from_t": 125.0}
    named = machine_row(spec_p, {**loops, "pump": pump_row})
    assert named["detected"] and named["delay_s"] == 20.0 and named["named"] == "pump"
    assert named["right_loop"] and named["first_alarm"] == "stick"
    assert named["explained_by_pump"] == ["stick", "boom"] and named["secondary"] == []
    assert fault_cell([named], LOOPS)["pump_named"] == 1
    cell = fault_cell([row, late, missed], LOOPS)
    assert (cell["runs"], cell["detected"], cell["named_right"]) == (3, 2, 1)
    assert cell["median_delay_s"] == 26.0  # (12 + 40) / 2
    assert cell["neighbour_alarm_runs"] == 3 and cell["neighbour_alarms"]["boom"] == 3
    assert cell["pre_onset_false_alarms"] == 1


def _recount(tmp: Path, spec: dict[str, Any], fault: str | None) -> dict[str, list[float]]:
    """The run simulated by `monitor simulate --machine` and each loop judged by `monitor
    detect --loop`: each loop's times of entry into the fault state, from its event lines."""
    csv = tmp / f"run_{spec['seed']}.csv"
    argv = [
        "simulate",
        "--machine",
        "excavator4",
        "--cycle",
        "mixed",
        "--seed",
        str(spec["seed"]),
        "--duration",
        f"{spec['duration_s']:g}",
        "--out",
        str(csv),
    ]
    if fault:
        argv += ["--fault", fault]
    assert main(argv) == 0
    config = str(resource_path("config", "excavator4.yaml"))
    entries = {}
    for loop in LOOPS:
        events = tmp / f"{spec['seed']}_{loop}.jsonl"
        argv = [
            "detect",
            str(csv),
            "--loop",
            loop,
            "--config",
            config,
            "--events",
            str(events),
            "--j-every",
            "0",
        ]
        assert main(argv) == 0
        lines = [json.loads(x) for x in events.read_text().splitlines()]
        states = [x for x in lines if x.get("event") == "state"]
        entries[loop] = [
            x["t"]
            for prev, x in zip([None, *states], states, strict=False)
            if x["state"] == "fault" and (prev is None or prev["state"] != "fault")
        ]
    return entries


def test_short_run_rows_match_an_independent_count(tmp_path: Path) -> None:
    out = tmp_path / "m.json"
    argv = [
        "eval-sim",
        "--machine",
        "excavator4",
        "--faults",
        "stick.spool_wear,boom.spool_wear",
        "--severities",
        "1",
        "--runs",
        "1",
        "--normal-hours",
        "0.05",
        "--duration",
        "180",
        "--onset",
        "60",
        "--json",
        str(out),
        "--markdown",
        str(tmp_path / "m.md"),
    ]
    assert main(argv) == 0
    result = json.loads(out.read_text())
    assert result["plan"] == {**result["plan"], "fault_runs": 2, "normal_runs": 1}
    assert "--machine excavator4" in result["rerun"] and "--onset 60" in result["rerun"]
    assert all(len(result["runs"]["normal"][n]) == 1 for n in LOOPS)
    normal = {n: result["runs"]["normal"][n][0] for n in LOOPS}
    counted = _recount(tmp_path, {"seed": normal["boom"]["seed"], "duration_s": 180}, None)
    for loop in LOOPS:
        assert normal[loop]["alarm_episodes"] == len(counted[loop]), loop
        fa = result["loops"][loop]["false_alarms_normal"]
        assert fa["alarm_episodes"] == len(counted[loop]) and fa["hours"] == 0.05
    raised = 0
    for row in result["runs"]["fault"]:
        counted = _recount(
            tmp_path, {"seed": row["seed"], "duration_s": 180}, f"{row['fault']}:1@60"
        )
        after = {n: [t for t in ts if t >= 60.0] for n, ts in counted.items()}
        for loop in LOOPS:
            mine = row["loops"][loop]
            assert mine["pre_onset_alarms"] == len(counted[loop]) - len(after[loop]), loop
            assert mine["detected"] == bool(after[loop])
            if after[loop]:
                assert mine["delay_s"] == pytest.approx(after[loop][0] - 60.0, abs=0.011)
        first = (
            min((ts[0], n) for n, ts in after.items() if ts)[1] if any(after.values()) else "none"
        )
        assert row["first_alarm"] == first
        # The machine's finding names the first loop unless the pump's rule alarmed or a
        # stronger loop alarmed within a second of it.
        pump = row["loops"].get("pump", {})
        if not pump.get("detected") and first != "none":
            t_first = row["loops"][first]["delay_s"]
            tied = [n for n in LOOPS if after[n] and after[n][0] - 60.0 - t_first <= 1.0]
            assert row["named"] in tied
        assert row["neighbours"] == sorted(n for n in LOOPS if after[n] and n != row["loop"])
        raised += row["detected"]
    assert raised >= 1  # full spool wear in a section's flow: seen (not vacuous)
    cells = {r["fault"]: r["all"] for r in result["faults"]}
    assert sum(c["detected"] for c in cells.values()) == raised
    assert "| stick.spool_wear | 1 | 1 |" in (tmp_path / "m.md").read_text()


@pytest.mark.parametrize(
    "argv",
    [
        ["--model", "shipped"],
        ["--presets", "default"],
        ["--no-twins"],
        ["--twin-residuals"],
        ["--faults", "stick.sand_in_oil"],
        ["--onset", "10"],
        ["--config", str(resource_path("config", "monitor.yaml"))],  # one loop, the boom
    ],
)
def test_machine_bad_arguments_exit_2(tmp_path: Path, argv: list[str]) -> None:
    json_path = tmp_path / "x.json"
    assert main(["eval-sim", "--machine", "excavator4", "--json", str(json_path), *argv]) == 2
    assert not json_path.exists()


def test_boom_evaluation_refuses_a_loop_fault(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["eval-sim", "--faults", "stick.spool_wear", "--json", str(tmp_path / "x")]) == 2
    assert "need --machine excavator4" in capsys.readouterr().err


def test_dask_workers_give_the_one_process_rows() -> None:
    """--workers 2 (a Dask LocalCluster) judges the same runs to the same rows."""
    from monitor.evaluation.machine_eval import judge_all

    plan = MachinePlan(
        faults=("bucket.spool_wear",),
        severities=(1.0,),
        runs=1,
        normal_hours=1 / 60,
        duration_s=105.0,
        onset_s=45.0,
    )
    config = resource_path("config", "excavator4.yaml")
    one, _ = judge_all(config, plan, workers=1)
    two, _ = judge_all(config, plan, workers=2)
    assert (one.normal, one.faults) == (two.normal, two.faults)
    assert len(one.faults) == 1 and all(len(rows) == 1 for rows in one.normal.values())
