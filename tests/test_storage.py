"""Storage: the event log rotates by size and continues across restarts, the quota deletes
the oldest black boxes first and then the oldest rotated event logs, never one with an
unsent alarm; every daemon event carries wall-clock and monotonic time.  Real files in
tmp_path; every size below is counted by hand."""

from __future__ import annotations

import dataclasses
import datetime as dt
import itertools
import json
import time
from pathlib import Path

import can
import pytest
from live_support import live_config, send_all, settle, write_config

from monitor.config.settings import BlackBoxConfig, load_config
from monitor.errors import ConfigError
from monitor.io.candump import read_candump
from monitor.live.blackbox import BlackBox
from monitor.live.daemon import Daemon
from monitor.live.eventlog import EventLog
from monitor.live.storage import Quota, rotated_logs
from monitor.resources import resource_path

T0 = 1_700_000_000.0
DT = 1 / 64  # exact in binary, so window edges are exact comparisons


def _padded(path: Path, record: dict, n_bytes: int) -> None:
    """One JSON line of exactly ``n_bytes`` (JSON allows trailing spaces)."""
    text = json.dumps(record)
    path.write_text(text + " " * (n_bytes - 1 - len(text)) + "\n")
    assert path.stat().st_size == n_bytes


@pytest.fixture
def store(tmp_path) -> tuple[Path, Path]:
    """3 black boxes of 1000 B (a oldest), event log 500 B, .1 400 B, .2 300 B (oldest):
    4200 B in all."""
    boxes = tmp_path / "bb"
    boxes.mkdir()
    for hour, name in enumerate("abc"):
        (boxes / f"alarm-20260101T0{hour}0000.000000Z-{name}.log").write_text("x" * 1000)
    ev = tmp_path / "ev.jsonl"
    _padded(ev, {"seq": 4, "state": "normal"}, 500)
    _padded(ev.with_name("ev.jsonl.1"), {"seq": 3, "state": "normal"}, 400)
    _padded(ev.with_name("ev.jsonl.2"), {"seq": 2, "state": "fault"}, 300)
    return boxes, ev


def _names(boxes: Path, ev: Path) -> list[str]:
    return sorted(p.name for p in [*boxes.iterdir(), *ev.parent.glob("ev.jsonl*")])


def test_quota_deletes_oldest_black_boxes_first(store) -> None:
    boxes, ev = store
    (ev.parent / "ev.jsonl.acked").write_text("2\n")  # the fault (seq 2) was uploaded
    q = Quota(3300, boxes, ev)
    assert q.enforce() == 3200  # 4200 - a
    assert [p.name[-5] for p in q.black_boxes()] == ["b", "c"]
    q.quota_bytes = 2300
    assert q.enforce() == 2200  # - b; the event logs untouched while boxes remain
    assert [p.name[-5] for p in q.black_boxes()] == ["c"] and len(rotated_logs(ev)) == 2
    q.quota_bytes = 1900
    assert q.enforce() == 1900  # - .2 (the oldest rotated log); c, the newest box, stays
    assert rotated_logs(ev) == [ev.with_name("ev.jsonl.1")]
    q.quota_bytes = 100
    assert q.enforce() == 1500  # - .1; the current log and the newest box are never deleted
    assert rotated_logs(ev) == [] and ev.exists() and q.over_quota == 1
    assert [p.name[-5] for p in q.black_boxes()] == ["c"]
    assert (q.deleted_black_boxes, q.deleted_event_logs) == (2, 2)


def test_quota_keeps_unsent_alarms(store) -> None:
    boxes, ev = store
    q = Quota(100, boxes, ev)
    # No .acked file: the fault in .2 is unsent, so .2 stays, and .1 behind it too; the
    # newest black box (c) stays too.
    assert q.enforce() == 2200
    assert len(q.black_boxes()) == 1 and len(rotated_logs(ev)) == 2 and q.over_quota == 1
    (ev.parent / "ev.jsonl.acked").write_text("1")
    assert q.enforce() == 2200  # acknowledged up to 1 < 2: still unsent
    (ev.parent / "ev.jsonl.acked").write_text("not a number")
    assert q.enforce() == 2200  # unreadable: nothing counts as acknowledged
    (ev.parent / "ev.jsonl.acked").write_text("2")
    assert q.enforce() == 1500
    assert _names(boxes, ev) == [
        "alarm-20260101T020000.000000Z-c.log",
        "ev.jsonl",
        "ev.jsonl.acked",
    ]


def test_sensor_fault_is_an_alarm_inactive_and_bus_lines_are_not(tmp_path) -> None:
    ev = tmp_path / "ev.jsonl"
    _padded(ev, {"seq": 4, "state": "normal"}, 100)
    _padded(ev.with_name("ev.jsonl.1"), {"seq": 3, "state": "sensor_fault"}, 100)
    _padded(ev.with_name("ev.jsonl.2"), {"seq": 2, "state": "fault", "kind": "bus"}, 100)
    _padded(ev.with_name("ev.jsonl.3"), {"seq": 1, "state": "inactive"}, 100)
    q = Quota(150, tmp_path / "bb", ev)
    # .3 and .2 deleted (a bus line in fault is not itself an alarm), .1 (sensor fault,
    # unsent) kept.
    assert q.enforce() == 200
    assert [p.name for p in rotated_logs(ev)] == ["ev.jsonl.1"]


def _normal(log: EventLog) -> dict:
    return log.stamp({"state": "normal"})  # '{"state": "normal", "seq": N}\n': 30 B, N < 10


def _lines(paths: list[Path]) -> list[dict]:
    return [json.loads(x) for p in paths for x in p.read_text().splitlines()]


def test_event_log_rotates_by_size_and_keeps_the_newest(tmp_path) -> None:
    path = tmp_path / "ev.jsonl"
    log = EventLog(path, rotate_bytes=100)  # three 30-byte lines per file
    for _ in range(9):
        log.write(_normal(log))
    log.close()
    rotated = rotated_logs(path)
    assert [p.name for p in rotated] == ["ev.jsonl.2", "ev.jsonl.1"]
    assert [[e["seq"] for e in _lines([p])] for p in [*rotated, path]] == [
        [1, 2, 3],
        [4, 5, 6],
        [7, 8, 9],
    ]
    assert all(p.stat().st_size == 90 for p in [*rotated, path])
    # 270 B over a 200 B quota: the oldest file goes, events 4-9 stay.
    assert Quota(200, tmp_path / "bb", path).enforce() == 180
    assert [e["seq"] for e in _lines([*rotated_logs(path), path])] == list(range(4, 10))


def test_event_log_rotation_never_deletes_unsent_alarm(tmp_path) -> None:
    path = tmp_path / "ev.jsonl"
    quota = Quota(200, tmp_path / "bb", path)
    log = EventLog(path, rotate_bytes=100, quota=quota)  # the quota runs after each write
    for i in range(9):
        log.write(log.stamp({"state": "fault" if i == 1 else "normal"}))
    log.close()
    # Event 2 is an unacknowledged fault: its file (.2, the oldest) is kept over the quota.
    assert [e["seq"] for e in _lines([*rotated_logs(path), path])] == list(range(1, 10))
    assert quota.over_quota > 0


def test_restart_appends_and_continues_seq(tmp_path) -> None:
    path = tmp_path / "ev.jsonl"
    log = EventLog(path, rotate_bytes=100)
    for _ in range(9):
        log.write(_normal(log))
    log.close()
    log = EventLog(path, rotate_bytes=100)
    assert log.last_seq == 9
    log.write(log.stamp({"state": "normal"}))  # 31 B: 90 + 31 > 100, so it rotates first
    log.close()
    assert [p.name for p in rotated_logs(path)] == ["ev.jsonl.3", "ev.jsonl.2", "ev.jsonl.1"]
    assert [e["seq"] for e in _lines([*rotated_logs(path), path])] == list(range(1, 11))


def test_line_torn_by_a_power_cut_stays_on_its_own(tmp_path) -> None:
    path = tmp_path / "ev.jsonl"
    path.write_text('{"state": "normal", "seq": 5}\n{"state": "fau')
    log = EventLog(path)
    assert log.last_seq == 5
    log.write(log.stamp({"state": "normal"}))
    log.close()
    lines = path.read_text().splitlines()
    assert lines[1] == '{"state": "fau'
    assert json.loads(lines[2]) == {"state": "normal", "seq": 6}


def _frame(i: int) -> can.Message:
    # candump line: "(1700000000.015625) can0 123#0000000000000000\n" = 19+1+4+1+4+16+1 = 46 B
    return can.Message(
        timestamp=T0 + i * DT, arbitration_id=0x123, is_extended_id=False, data=bytes(8)
    )


def test_black_box_quota_deletes_oldest_box_never_the_one_recording(tmp_path) -> None:
    # pre 0.5 s = 32 frames before the alarm's + the alarm's own; post 0.25 s = 16 frames:
    # 49 lines of 46 B = 2254 B per box; the pre-alarm part alone 33 * 46 = 1518 B.
    cfg = BlackBoxConfig(directory=tmp_path / "bb", pre_s=0.5, post_s=0.25)
    quota = Quota(2 * 2254 + 100, cfg.directory, tmp_path / "ev.jsonl")
    box = BlackBox(cfg, quota=quota)
    names = []
    for i in range(400):
        box.add(_frame(i))
        if i in (100, 200, 300):
            names.append(box.trigger(T0 + i * DT, f"n{i}").name)
    box.close()
    # At the third start: 2254 + 2254 + 1518 = 6026 B > 4608 B, so the first box goes.
    assert [p.name for p in quota.black_boxes()] == names[1:]
    assert all(p.stat().st_size == 2254 for p in quota.black_boxes())
    quota.quota_bytes = 1000  # under one box: the oldest goes, the newest stays
    assert quota.enforce(recording=cfg.directory / names[2]) == 2254
    assert [p.name for p in quota.black_boxes()] == names[2:]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("storage:\n  quota_mb: 0\n", "storage.quota_mb must be > 0"),
        ("storage:\n  quota_mb: lots\n", "storage.quota_mb must be a number"),
        (
            "storage:\n  quota_mb: 10\n",
            "storage.quota_mb (10) must be more than twice event_log.rotate_mb (8)",
        ),
        ("storage:\n  quota: 10\n", "unknown key storage.quota"),
        ("storage:\n  writer_queue: 2\n", "storage.writer_queue must be >= 10"),
        ("event_log:\n  rotate_mb: -1\n", "event_log.rotate_mb must be >= 0.001"),
    ],
)
def test_bad_storage_config_is_one_clear_error(tmp_path, extra: str, message: str) -> None:
    with pytest.raises(ConfigError) as exc:
        load_config(write_config(tmp_path, extra))
    assert message in str(exc.value) and str(tmp_path / "monitor.yaml") in str(exc.value)


def test_storage_config_in_bytes(tmp_path) -> None:
    cfg = load_config(
        write_config(tmp_path, "storage:\n  quota_mb: 1.5\nevent_log:\n  rotate_mb: 0.25\n")
    )
    assert (cfg.storage.quota_bytes, cfg.event_log.rotate_bytes) == (1_500_000, 250_000)


def test_daemon_events_carry_wall_and_monotonic_time_and_restart_appends(tmp_path) -> None:
    """Two daemons in turn on one event log, each fed the first 1,500 frames of the normal
    log: one event (normal) each."""
    msgs = list(itertools.islice(read_candump(resource_path("replay", "normal.log")), 1500))
    path = tmp_path / "events.jsonl"
    hooked: list[dict] = []
    marks = [time.monotonic()]
    for run in ("a", "b"):
        cfg = live_config(tmp_path / run)
        cfg = dataclasses.replace(cfg, event_log=dataclasses.replace(cfg.event_log, path=path))
        daemon = Daemon(cfg, on_event=hooked.append)
        with can.Bus(
            interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True
        ) as sender:
            daemon.start()
            try:
                settle(daemon, send_all(sender, msgs))
            finally:
                daemon.stop()
        assert daemon.error is None
        marks.append(time.monotonic())
    on_disk = [json.loads(x) for x in path.read_text().splitlines()]
    assert on_disk == hooked and len(on_disk) == 2  # the second daemon appended
    assert [e["seq"] for e in on_disk] == [1, 2]
    for e, lo, hi in zip(on_disk, marks[:-1], marks[1:], strict=True):
        assert lo <= e["mono"] <= hi
        wall = dt.datetime.fromtimestamp(msgs[0].timestamp + e["t"], tz=dt.timezone.utc)
        assert dt.datetime.fromisoformat(e["time"]) == wall
        assert {"t", "time", "state", "J", "threshold", "fault"} <= set(e)
