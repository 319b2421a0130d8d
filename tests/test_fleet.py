"""`monitor fleet run` on a LocalCluster of 2 workers: per log exactly `monitor detect` with
the machine's model, the default model without commissioning, incremental reruns, bad input
as rows, and a killed client that loses nothing finished."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from monitor.cli import main
from monitor.model.modelfile import load_model
from tests.fleet_support import copy_fleet, env, fleet_cmd, kill, make_fleet, rows, wait_for


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    return make_fleet(tmp_path_factory.mktemp("fleet"), tmp_path_factory)


@pytest.fixture(scope="module")
def run1(fleet, tmp_path_factory):
    """The fleet plus bad input: a machine without logs, one whose logs lie outside logs/,
    an unreadable log, a log of another machine type (a CSV without the loop's signals) and
    a machine without commissioning."""
    where = tmp_path_factory.mktemp("run1")
    f = copy_fleet(fleet, where / "fleet")
    (f / "M09" / "logs").mkdir(parents=True)
    (f / "M08").mkdir()
    shutil.copy(fleet / "M01" / "logs" / "day01.log", f / "M08" / "day01.log")
    (f / "M01" / "logs" / "day03.log").write_bytes(b"\x00\x01garbage, not a candump log\n")
    (f / "M02" / "logs" / "day03.csv").write_text("t,Swing,Bucket\n0,1,2\n0.01,1,2\n")
    shutil.copytree(fleet / "M03" / "logs", f / "M04" / "logs")
    out = where / "results"
    proc = subprocess.run(
        fleet_cmd(str(f), "--out", str(out), "--workers", "2"),
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 3, proc.stderr  # logs failed: each is a row with its error
    return f, out, proc.stderr


def test_every_log_is_one_row_and_bad_input_is_a_row_with_its_reason(run1):
    f, out, err = run1
    by_log = {r["log"]: r for r in rows(out)}
    expected = {p.relative_to(f).as_posix() for p in f.glob("*/logs/*")} | {
        "M09/logs/",
        "M08/logs/",
    }
    assert set(by_log) == expected and len(rows(out)) == len(expected)
    assert "no logs" in by_log["M09/logs/"]["error"]
    assert "no logs" in by_log["M08/logs/"]["error"]
    assert by_log["M01/logs/day03.log"]["error"] and by_log["M01/logs/day03.log"]["verdict"] == (
        "not_judged"
    )
    assert by_log["M02/logs/day03.csv"]["error"]
    assert all(
        r["error"] is None for log, r in by_log.items() if log.endswith(("01.log", "02.log"))
    )
    assert "Dask dashboard http" in err and "logs," in err and "frames/s" in err


def test_the_last_line_counts_judged_not_judged_and_failed_and_names_the_first(run1):
    _f, out, err = run1
    got = rows(out)
    failed = sorted(r["log"] for r in got if r["error"] is not None)
    assert failed == ["M01/logs/day03.log", "M02/logs/day03.csv", "M08/logs/", "M09/logs/"]
    not_judged = sum(r["error"] is None and r["verdict"] == "not_judged" for r in got)
    judged = len(got) - len(failed) - not_judged
    last = err.strip().splitlines()[-1]
    assert last.startswith(
        f"fleet: {len(got)} logs: {judged} judged, {not_judged} not judged, "
        "4 failed (M01/logs/day03.log: "
    )
    assert "; M02/logs/day03.csv: " in last and "; 2 more); " in last
    assert f"{len(got) - 2} new this run, 0 already in results" in last


def test_drift_is_the_logs_median_j_over_the_commissioning_runs(run1, tmp_path):
    # p50_j_drift: the median of J over the log (every judged sample's J, as `monitor
    # detect --j-every 0.01` prints it) over the median J of the machine's own held-out
    # normal data, which `monitor train` keeps in the model file.
    f, out, _err = run1
    r = next(r for r in rows(out) if r["log"] == "M01/logs/day02.log")
    model = out / "models" / "M01.model.npz"
    j_median = load_model(model).training["j_median"]
    lines = tmp_path / "e.jsonl"
    main(
        [
            "detect",
            str(f / r["log"]),
            "--model",
            str(model),
            "--j-every",
            "0.01",
            "--events",
            str(lines),
        ]
    )
    js = [
        e["J"]
        for e in map(json.loads, lines.read_text().splitlines())
        if e.get("event") == "j" and e.get("J") is not None
    ]
    assert len(js) > 1000
    assert r["p50_j_drift"] == pytest.approx(float(np.median(js)) / j_median, rel=1e-6)


def test_the_page_of_a_simulated_fleet_says_whether_it_warned_before_the_alarm(run1, tmp_path):
    # Two judged logs a machine are too few for any trend (a warning needs four), so each
    # machine's column is "-" or no warning before its first alarming log.
    _f, out, _err = run1
    assert main(["fleet", "report", str(out), "--out", str(tmp_path / "page")]) == 0
    page = (tmp_path / "page" / "fleet.md").read_text()
    per: dict[str, list[dict]] = {}
    for r in sorted(rows(out), key=lambda r: r["log"]):
        per.setdefault(r["machine"], []).append(r)
    # The wearing machines alarmed only when judged with the default model (M04, without
    # commissioning), whose alarms are withheld: the page says "-" for every machine.
    for mid, mine in per.items():
        at = next((i for i, r in enumerate(mine, 1) if r["alarm"]), None)
        name = None if at is None else mine[at - 1]["log"].rsplit("/", 1)[1].split(".")[0]
        want = "-" if at is None else f"no warning before the alarm at log {at} ({name})"
        line = next(ln for ln in page.splitlines() if ln.startswith(f"| {mid} |"))
        assert f" | {want} | " in line


def test_no_commissioning_uses_the_default_model_and_says_so(run1):
    _f, out, err = run1
    assert "M04: no commissioning data, judged with the default model" in err
    m04 = [r for r in rows(out) if r["machine"] == "M04"]
    assert m04 and all(r["model"] == "default" for r in m04)
    assert all(r["model"] == "commissioned" for r in rows(out) if r["machine"] == "M01")
    # Judged with the shipped model, commissioned on the reference machine: said so, and
    # never a confident fault; a machine's own model is no reference.
    assert all(r["reference_model"] and r["verdict"] != "fault" and not r["alarm"] for r in m04)
    others = [r for r in rows(out) if r["machine"] != "M04" and r["error"] is None]
    assert others and all(r["reference_model"] is False for r in others)
    # A commissioned model records its machine (the machine's folder), as `monitor train`
    # records the config's machine_id.
    assert load_model(out / "models" / "M01.model.npz").card.machine_id == "M01"


def test_each_row_and_its_events_equal_monitor_detect_with_the_machines_model(run1, tmp_path):
    f, out, _err = run1
    events = pq.read_table(out / "events.parquet").to_pylist()
    judged = [r for r in rows(out) if r["error"] is None]
    assert len(judged) == 8
    for r in judged:
        summary, lines = tmp_path / "s.json", tmp_path / "e.jsonl"
        model = out / "models" / f"{r['machine']}.model.npz"
        config = tmp_path / "machine.yaml"  # the fleet judges each machine as itself
        config.write_text(f"machine_id: {r['machine']}\n")
        rc = main(
            [
                "detect",
                str(f / r["log"]),
                "--config",
                str(config),
                "--model",
                str(model),
                "--j-every",
                "0",
                "--summary",
                str(summary),
                "--events",
                str(lines),
            ]
        )
        s = json.loads(summary.read_text())
        assert rc == (3 if s["verdict"] == "not_judged" else 0)
        assert (r["verdict"], r["alarm"], r["fault"], r["sensor_fault"]) == (
            s["verdict"],
            s["alarm"],
            s["fault"],
            s["sensor_fault"],
        )
        assert r["max_j"] == s["max_J"] and r["eps0"] == s["threshold"]
        assert r["reference_model"] == s["reference_model"]
        assert r["max_j_ratio"] == (None if s["max_J"] is None else s["max_J"] / s["threshold"])
        assert r["judged_s"] == s["judged_s"] and r["first_alarm_t"] == s["first_alarm_t"]
        assert json.loads(r["rejected"]) == s["rejected"]
        mine = [json.loads(e["event"]) for e in events if e["log"] == r["log"]]
        theirs = [json.loads(line) for line in lines.read_text().splitlines()]
        assert mine == theirs


def test_rerun_is_incremental(run1, tmp_path):
    f, out, _err = run1
    before = rows(out)
    res = tmp_path / "r"
    shutil.copytree(out, res)
    shutil.copy(f / "M01" / "logs" / "day02.log", f / "M01" / "logs" / "day04.log")
    proc = subprocess.run(
        fleet_cmd(str(f), "--out", str(res), "--workers", "1"),
        capture_output=True,
        text=True,
        env=env(),
    )
    (f / "M01" / "logs" / "day04.log").unlink()
    assert proc.returncode == 3, proc.stderr  # run1's failed logs are still there
    assert "1 new this run" in proc.stderr.splitlines()[-1]
    # Only M01 has a new log, and its commissioning is unchanged: its model is reused.
    assert "fleet: 1 machine model(s) reused (commissioning unchanged)" in proc.stderr
    after = rows(res)
    assert len(after) == len(before) + 1
    assert len({r["log"] for r in after}) == len(after)


def test_new_commissioning_data_trains_the_machine_again(run1, tmp_path):
    f, out, _err = run1
    g, res = copy_fleet(f, tmp_path / "fleet"), tmp_path / "r"
    shutil.copytree(out, res)
    old_model = (res / "models" / "M02.model.npz").read_bytes()
    # M02 is commissioned again (another recording) and sends a new log.
    shutil.copy(
        g / "M01" / "commissioning" / "normal.log", g / "M02" / "commissioning" / "again.log"
    )
    shutil.copy(g / "M02" / "logs" / "day02.log", g / "M02" / "logs" / "day04.log")
    proc = subprocess.run(
        fleet_cmd(str(g), "--out", str(res), "--workers", "1"),
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 3, proc.stderr  # run1's failed logs are still there
    assert "reused" not in proc.stderr
    assert (res / "models" / "M02.model.npz").read_bytes() != old_model
    meta = json.loads((res / "models" / "M02.trained-from.json").read_text())
    assert sorted(meta["commissioning"]) == [
        "M02/commissioning/again.log",
        "M02/commissioning/normal.log",
    ]


def test_a_model_trained_with_other_settings_is_commissioned_again(run1, tmp_path):
    # Results written by a monitor that commissioned otherwise (its trained-from.json has no
    # training settings: the last quarter held out, the bias statistic on): after an
    # upgrade the machine is commissioned again, not judged with the old model.
    f, out, _err = run1
    g, res = copy_fleet(f, tmp_path / "fleet"), tmp_path / "r"
    shutil.copytree(out, res)
    meta_path = res / "models" / "M01.trained-from.json"
    meta = json.loads(meta_path.read_text())
    del meta["train"]
    meta_path.write_text(json.dumps(meta))
    shutil.copy(g / "M01" / "logs" / "day02.log", g / "M01" / "logs" / "day04.log")
    proc = subprocess.run(
        fleet_cmd(str(g), "--out", str(res), "--workers", "1"),
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 3, proc.stderr  # run1's failed logs are still there
    assert "reused" not in proc.stderr
    again = json.loads(meta_path.read_text())
    assert again["train"] == {"folds": 4, "lend": True, "support_check": True}
    assert again["commissioning"] == meta["commissioning"]


def test_b_too_thin_in_commissioning_is_off_with_the_rules_reason_in_the_fleets_record(
    run1, tmp_path
):
    # Each machine's commissioning run is 180 s: too short to cross-fit 4 folds of 60 s
    # blocks (8 blocks, 8 min), so its last quarter, 45 s (0.75 min), is held out, and the
    # bias statistic needs 8 windows of 60 s (8 min) of it: off, with those numbers.
    _f, out, _err = run1
    for mid in ("M01", "M02", "M03"):
        stats = json.loads((out / "models" / f"{mid}.trained-from.json").read_text())["statistics"]
        assert stats["J"].startswith("on"), stats  # J stays on (thinly supported: said)
        b = stats["B"]
        assert b.startswith("off: ") and "the bias statistic needs 8 min (8 windows)" in b, b
        held_min = float(b.removeprefix("off: ").split(" min")[0])
        assert 0.5 <= held_min <= 0.75, b  # at most the last quarter of 3 min
        assert stats["L"].startswith("off"), stats  # L watches only with B
        assert stats["H"].startswith("off"), stats  # not asked for, as monitor train
        assert load_model(out / "models" / f"{mid}.model.npz").bias is None
    # The table of the fleet page says it beside the machine's model, the web page on the
    # machine's own page with the reason.
    web = tmp_path / "web"
    page = main(["fleet", "report", str(out), "--out", str(tmp_path / "page"), "--html", str(web)])
    assert page == 0
    table = (tmp_path / "page" / "fleet.md").read_text()
    m01 = next(line for line in table.splitlines() if line.startswith("| M01 |"))
    assert "statistics on: J; off: B, L, H" in m01, m01
    (why,) = [line for line in table.splitlines() if line.startswith("- M01: B off: ")]
    assert "the bias statistic needs 8 min (8 windows)" in why, why
    assert "statistics on: J; off: B, L, H" in (web / "index.html").read_text()
    machine = (web / "machine-M01.html").read_text()
    assert "<li><b>B</b> off: " in machine and "needs 8 min (8 windows)" in machine


def _started_with_a_finished_log(fleet, tmp_path) -> tuple[Path, Path, subprocess.Popen]:
    """A run on a copy of ``fleet`` in its own process group, once it has a finished log."""
    f = copy_fleet(fleet, tmp_path / "fleet")
    out = tmp_path / "results"
    proc = subprocess.Popen(
        fleet_cmd(str(f), "--out", str(out), "--workers", "2"),
        stderr=subprocess.PIPE,
        text=True,
        env=env(),
        start_new_session=True,
    )
    parts = out / "parts"
    wait_for(lambda: parts.is_dir() and any(parts.glob("*.json")), "a first finished log", proc)
    return f, out, proc


def _rerun_resumes(f: Path, out: Path) -> None:
    """A second run judges only what the first did not finish, and every log has one row."""
    finished = len(list((out / "parts").glob("*.json")))
    total = len(list(f.glob("*/logs/*.log")))
    again = subprocess.run(
        fleet_cmd(str(f), "--out", str(out), "--workers", "2"),
        capture_output=True,
        text=True,
        env=env(),
    )
    assert again.returncode == 0, again.stderr
    assert f"{total - finished} new this run, {finished} already in results" in again.stderr
    logs = [r["log"] for r in rows(out)]
    assert sorted(logs) == sorted(p.relative_to(f).as_posix() for p in f.glob("*/logs/*.log"))


def test_a_killed_client_loses_nothing_finished_and_writes_no_row_twice(fleet, tmp_path):
    f, out, proc = _started_with_a_finished_log(fleet, tmp_path)
    kill(proc)  # the client and its LocalCluster's workers (one process group)
    _rerun_resumes(f, out)


def test_ctrl_c_stops_in_one_line_with_130_leaves_no_table_and_a_rerun_resumes(fleet, tmp_path):
    # Ctrl-C at a terminal: SIGINT to the whole process group (the client and its local
    # workers).  Before: ~120 lines of Dask tracebacks and an empty logs.parquet, on which
    # `fleet report` died of a ZeroDivisionError.
    f, out, proc = _started_with_a_finished_log(fleet, tmp_path)
    try:
        os.killpg(proc.pid, signal.SIGINT)
        _o, err = proc.communicate(timeout=120)
    finally:
        kill(proc)
    assert proc.returncode == 130, err
    lines = err.strip().splitlines()
    assert lines[-1].startswith("monitor fleet: interrupted: ")
    assert "run again to resume" in lines[-1]
    assert all(ln.startswith("fleet: ") for ln in lines[:-1]), err  # nothing of Dask's
    assert not (out / "logs.parquet").exists() and not (out / "events.parquet").exists()
    report = subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "fleet",
            "report",
            str(out),
            "--out",
            str(tmp_path / "page"),
        ],
        capture_output=True,
        text=True,
        env=env(),
    )
    assert report.returncode == 2 and "run `monitor fleet run` first" in report.stderr
    assert len(report.stderr.strip().splitlines()) == 1
    _rerun_resumes(f, out)
