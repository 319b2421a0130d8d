"""`monitor fleet run` on whole machines (config/excavator4.yaml): a row per (log, loop), each
loop commissioned as `monitor train --loop` and judged as `monitor detect --loop`; a loop
without its machine's own model uncommissioned, never healthy; the page's machine verdict
naming the loop."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pyarrow.parquet as pq
import pytest

from monitor.fleet.loops import cell, loop_order, machine_verdict
from monitor.fleet.simulate import FleetPlan
from monitor.fleet.simulate_whole import simulate_whole_fleet
from monitor.fleet.store import ResultStore
from monitor.resources import resource_path
from tests.fleet_support import env

CONFIG = str(resource_path("config", "excavator4.yaml"))
LOOPS = ["boom", "stick", "bucket", "swing"]


def _row(log: str, loop: str | None, verdict: str, **kw) -> dict:
    return {
        "machine": log.split("/")[0],
        "log": log,
        "loop": loop,
        "sha256": "ab",
        "verdict": verdict,
        "error": None,
        "model": "commissioned",
        "reference_model": False,
        **kw,
    }


def test_the_machine_verdict_names_the_faulty_loop_and_never_calls_an_unjudged_loop_healthy():
    old = [_row("M01/logs/day01.log", loop, "fault") for loop in LOOPS]  # not the newest
    new = [
        _row("M01/logs/day02.log", "swing", "not_judged", model="default"),
        _row("M01/logs/day02.log", "boom", "healthy"),
        _row("M01/logs/day02.log", "stick", "fault"),
        _row("M01/logs/day02.log", "bucket", "healthy"),
    ]
    v = machine_verdict("M01", old + new)
    assert v.log == "M01/logs/day02.log"
    assert v.cells == {
        "boom": "healthy",
        "stick": "fault",
        "bucket": "healthy",
        "swing": "uncommissioned",
    }
    assert (v.state, v.text) == ("fault", "FAULT: stick; uncommissioned: swing")
    healthy = [_row("M02/logs/d.log", loop, "healthy") for loop in LOOPS]
    assert machine_verdict("M02", healthy).text == "healthy"
    # Judged with another machine's model (its alarms withheld): uncommissioned, and the
    # judged loops are said beside it.
    healthy[3] = _row("M02/logs/d.log", "swing", "healthy", reference_model=True)
    assert machine_verdict("M02", healthy).text == (
        "uncommissioned: swing; healthy: boom, stick, bucket"
    )
    assert cell(_row("x", "boom", "sensor_fault", reference_model=True)) == "sensor_fault"
    assert cell(_row("x", "boom", "healthy", error="InputFileError: ...")) == "error"
    assert loop_order({"swing", "aux", "boom", "bucket", "stick"}) == [*LOOPS, "aux"]


def test_the_store_keeps_a_row_per_log_and_loop_with_the_loop_column_last(tmp_path):
    store = ResultStore(tmp_path)
    for loop in ("swing", "boom"):
        store.add(
            _row("M01/logs/day01.log", loop, "healthy"),
            [{"t": 1.0, "state": "normal", "fault": None}],
        )
    store.add(_row("M02/logs/day01.log", None, "healthy"), [])
    assert store.done() == {
        ("M01/logs/day01.log", "swing", "ab"),
        ("M01/logs/day01.log", "boom", "ab"),
        ("M02/logs/day01.log", "", "ab"),
    }
    store.compact()
    logs = pq.read_table(tmp_path / "logs.parquet")
    # `loop` after the columns of one-loop fleets; only the whole machine's columns after it
    names = logs.column_names
    assert names[names.index("loop") + 1 :] == [
        "not_judged_why",
        "alarm_since_t",
        "finding",
        "finding_role",
    ]
    assert [(r["log"], r["loop"]) for r in logs.to_pylist()] == [
        ("M01/logs/day01.log", "boom"),
        ("M01/logs/day01.log", "swing"),
        ("M02/logs/day01.log", None),
    ]
    events = pq.read_table(tmp_path / "events.parquet").to_pylist()
    assert [e["loop"] for e in events] == ["boom", "swing"]
    # The same log and loop again (a rerun of a changed file): one row, its newest.
    store.add(_row("M01/logs/day01.log", "boom", "fault", sha256="cd"), [])
    store.compact()
    rows = pq.read_table(tmp_path / "logs.parquet").to_pylist()
    assert [(r["loop"], r["sha256"], r["verdict"]) for r in rows[:2]] == [
        ("boom", "cd", "fault"),
        ("swing", "ab", "healthy"),
    ]


@pytest.fixture(scope="module")
def judged(tmp_path_factory):
    """Two whole machines, two 60 s logs each (severity 0, then 0.6): M01 wears its stick's
    piston seal and has no commissioning log; M02 wears its bucket's spool and is
    commissioned on its 180 s warming run."""
    where = tmp_path_factory.mktemp("loops")
    fleet = where / "F"
    plan = FleetPlan(machines=2, days=1, logs_per_day=2, log_s=60.0, commissioning_s=180.0)
    key = simulate_whole_fleet(fleet, plan, say=lambda _m: None)
    shutil.rmtree(fleet / "M01" / "commissioning")
    results = where / "R"
    cmd = [sys.executable, "-m", "monitor", "fleet", "run", str(fleet), "--out", str(results)]
    proc = subprocess.run(
        [*cmd, "--config", CONFIG, "--workers", "1"], capture_output=True, text=True, env=env()
    )
    assert proc.returncode == 0, proc.stderr
    return fleet, results, key, proc.stderr


def test_every_loop_of_every_log_is_a_row_and_the_worn_loop_alone_alarms(judged):
    _fleet, results, key, stderr = judged
    rows = {(r["log"], r["loop"]): r for r in pq.read_table(results / "logs.parquet").to_pylist()}
    logs = [d["log"] for m in key["machines"].values() for d in m["days"]]
    # The config's `pump:` adds the shared pump, a row of its own per log.
    assert sorted(rows) == sorted((log, loop) for log in logs for loop in [*LOOPS, "pump"])
    # M01 has no commissioning data: none of its loops is judged (the config's loop models
    # are not this machine's), nor its pump (no margin law of its own), and none reads healthy.
    for log in logs[:2]:
        for loop in [*LOOPS, "pump"]:
            r = rows[(log, loop)]
            assert (r["verdict"], r["model"], r["error"]) == ("not_judged", "default", None)
        assert rows[(log, "pump")]["not_judged_why"].startswith("no commissioning data")
    # M02's 180 s of commissioning hold too little steady open flow for the pump's threshold
    # (the support rule): commissioned, its rule off, not judged with the reason.
    for log in logs[2:]:
        r = rows[(log, "pump")]
        assert (r["verdict"], r["model"], r["alarm"]) == ("not_judged", "commissioned", False)
        why = r["not_judged_why"]
        assert "the pump's law needs" in why or "independent windows" in why, why
    # M02: the key says its bucket's spool is worn 0.6 in its second log, nothing before.
    assert [d["fault"] for d in key["machines"]["M02"]["days"]] == [None, "bucket.spool_wear"]
    alarms = {(log, loop) for (log, loop), r in rows.items() if r["alarm"]}
    assert alarms == {("M02/logs/day01-2.log", "bucket")}
    for log in logs[2:]:
        assert {rows[(log, loop)]["model"] for loop in LOOPS} == {"commissioned"}
    assert "20 log loops: 8 judged, 12 not judged, 0 failed" in stderr.splitlines()[-1]


def test_each_loop_model_is_train_loops_and_a_row_is_what_detect_loop_says(judged, tmp_path):
    from monitor.model.modelfile import load_model

    fleet, results, _key, _ = judged
    for loop in LOOPS:
        model = load_model(results / "models" / f"M02.{loop}.model.npz")
        assert (model.card.loop, model.card.machine_id) == (loop, "M02")
        # a section model reads the other loops' spool commands, as `train --loop` makes it
        others = {f"SpoolCmd@{o}" for o in LOOPS if o != loop}
        assert others <= set(model.spec.variables)
    assert not (results / "models" / "M01.stick.trained-from.json").exists()
    row = next(
        r
        for r in pq.read_table(results / "logs.parquet").to_pylist()
        if (r["log"], r["loop"]) == ("M02/logs/day01-2.log", "bucket")
    )
    summary = tmp_path / "s.json"
    cmd = [sys.executable, "-m", "monitor", "detect", str(fleet / row["log"]), "--loop", "bucket"]
    model = results / "models" / "M02.bucket.model.npz"
    proc = subprocess.run(
        [*cmd, "--config", CONFIG, "--model", str(model), "--summary", str(summary)],
        capture_output=True,
        text=True,
        env=env(),
    )
    s = json.loads(summary.read_text())
    # detect declares the config's machine (none): the model's machine M02 is not it, so
    # its alarm is withheld (not judged, exit 3); the fleet judges as machine M02 and
    # alarms.  The detector's numbers are the same.
    assert proc.returncode == 3 and s["verdict"] == "not_judged" and s["withheld"], proc.stderr
    assert row["alarm"] and row["verdict"] == "fault"
    assert (row["max_level"], row["samples"], row["max_j"], row["judged_s"]) == (
        s["max_level"],
        s["samples"],
        s["max_J"],
        s["judged_s"],
    )


def test_the_report_names_the_loop_and_says_uncommissioned(judged, tmp_path):
    _fleet, results, _key, _ = judged
    out = tmp_path / "md"
    proc = subprocess.run(
        [sys.executable, "-m", "monitor", "fleet", "report", str(results), "--out", str(out)],
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 0, proc.stderr
    page = (out / "fleet.md").read_text()
    assert (
        "| M01 | M01/logs/day01-2.log | uncommissioned: boom, stick, bucket, swing, pump | "
        "uncommissioned | uncommissioned | uncommissioned | uncommissioned | uncommissioned |"
    ) in page
    assert (
        "| M02 | M02/logs/day01-2.log | FAULT: bucket; not judged: pump | healthy | healthy | "
        "fault | healthy | not judged |"
    ) in page
    assert "- M02 pump: not judged: " in page
    assert "| M02 bucket | 2 | fault |" in page
