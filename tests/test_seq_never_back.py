"""``seq`` never goes back and a rotation never replaces a file: what an uploader relies on to
know which alarms it still has to take off the machine.

The unit cases run the event log in this process; the restart case runs the attack harness
(``monitor run``, a replayer and a sniffer, each a process of its own on a udp_multicast
port of its own; tests/attack_support.py)."""

from __future__ import annotations

import json
from pathlib import Path

from monitor.live.eventlog import EventLog, seq_path
from monitor.live.storage import Quota, ack_path, rotated_logs


def _lines(*paths: Path) -> list[dict]:
    return [json.loads(x) for p in paths for x in p.read_bytes().splitlines()]


def _alarm(log: EventLog) -> dict:
    return log.stamp({"state": "fault", "fault": "piston_wear"})


def test_numbering_goes_on_above_acked_when_logs_and_seq_are_gone(tmp_path) -> None:
    """Logs and .seq taken away, .acked (50) left: the next event is 51, not 1, so the new
    alarms are unsent and the quota keeps every one of them."""
    ev = tmp_path / "ev.jsonl"
    ack_path(ev).write_text("50\n")
    quota = Quota(150, tmp_path / "bb", ev)  # room for about two 50-byte lines
    log = EventLog(ev, rotate_bytes=120, quota=quota)
    assert log.last_seq == 50
    for _ in range(9):
        log.write(_alarm(log))
    log.close()
    seqs = [e["seq"] for e in _lines(*rotated_logs(ev), ev)]
    assert seqs == list(range(51, 60))  # nothing deleted: all unsent, over the quota
    assert quota.deleted_event_logs == 0 and quota.over_quota > 0
    assert int(seq_path(ev).read_text()) == 59


def test_numbering_takes_the_largest_of_seq_tails_and_acked(tmp_path) -> None:
    ev = tmp_path / "ev.jsonl"
    ev.write_text('{"seq": 7, "state": "normal"}\n')
    ev.with_name("ev.jsonl.2").write_text('{"seq": 30, "state": "normal"}\n')  # not the newest
    seq_path(ev).write_text(f"{12:020d}\n")
    ack_path(ev).write_text("20")
    log = EventLog(ev)
    assert log.last_seq == 30  # the largest anywhere, not the first tail found
    log.close()


def test_rotation_leaves_a_stray_name_alone_and_overwrites_nothing(tmp_path) -> None:
    """A stray ``ev.jsonl.01`` beside the rotated logs: rotations go on around it, the log
    holding the unsent fault survives, and every seq is issued once."""
    ev = tmp_path / "ev.jsonl"
    log = EventLog(ev, rotate_bytes=100)
    for i in range(4):  # 1..3 in .1 after the rotation at 4; 2 is a fault
        log.write(_alarm(log) if i == 1 else log.stamp({"state": "normal"}))
    log.close()
    stray = ev.with_name("ev.jsonl.01")
    stray.write_text('{"seq": 1, "state": "normal", "planted": true}\n')
    log = EventLog(ev, rotate_bytes=100)
    for _ in range(8):  # three more rotations
        log.write(log.stamp({"state": "normal"}))
    log.close()
    assert stray.read_text() == '{"seq": 1, "state": "normal", "planted": true}\n'
    files = [*rotated_logs(ev), ev]
    assert [p.name for p in files] == [f"ev.jsonl.{n}" for n in (4, 3, 2, 1)] + ["ev.jsonl"]
    seqs = [e["seq"] for e in _lines(*files)]
    assert seqs == list(range(1, 13))  # each once, in order
    assert [e["seq"] for e in _lines(*files) if e["state"] == "fault"] == [2]
    log = EventLog(ev, rotate_bytes=100)
    assert log.last_seq == 12
    log.close()


def test_rotation_never_renames_onto_a_planted_file(tmp_path, monkeypatch) -> None:
    """A file planted at the name the rotation is about to use (``.1`` while it runs): the
    rotation is refused (logged, counted) and the events go on in the current file."""
    ev = tmp_path / "ev.jsonl"
    log = EventLog(ev, rotate_bytes=100)
    for _ in range(3):
        log.write(log.stamp({"state": "normal"}))
    planted = ev.with_name("ev.jsonl.1")
    planted.write_text("someone else's file\n")
    real = rotated_logs

    def no_rotated(path: Path) -> list[Path]:  # the planted file is not seen in the listing
        return [p for p in real(path) if p != planted]

    monkeypatch.setattr("monitor.live.eventlog.rotated_logs", no_rotated)
    log.write(log.stamp({"state": "normal"}))
    monkeypatch.undo()
    log.close()
    assert planted.read_text() == "someone else's file\n"
    assert log.rotations == 0 and log.disk_errors >= 1
    assert [e["seq"] for e in _lines(ev)] == [1, 2, 3, 4]


def test_a_write_after_close_reopens_the_log_and_its_seq_file(tmp_path) -> None:
    """An event that comes after the close (a disk job queued behind it) is written, and its
    ``seq`` saved: the log and its .seq file open again, as after a failed write."""
    ev = tmp_path / "ev.jsonl"
    log = EventLog(ev)
    log.write(_alarm(log))
    log.close()
    log.write(_alarm(log))
    log.close()
    assert [e["seq"] for e in _lines(ev)] == [1, 2]
    assert int(seq_path(ev).read_text()) == 2
    assert log.disk_errors == 0 and log.unwritten == 0
