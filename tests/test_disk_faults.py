"""Disk faults: the event log loses no event and keeps ``seq`` contiguous on a full disk, a
failed rotation, a moved or damaged log; a full disk deletes no black box elsewhere, nor the
one being recorded; nothing is written through a planted link, an
``.acked`` FIFO blocks nothing, black-box names never collide, and a failing job never
ends the writer thread.

The full-disk cases run on a real 1 MB tmpfs mounted by the test (root only; skipped with
the reason otherwise): ENOSPC comes from the kernel, not from a mock.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from monitor.config.settings import BlackBoxConfig
from monitor.errors import ConfigError
from monitor.live.blackbox import BlackBox
from monitor.live.eventlog import EventLog, seq_path
from monitor.live.storage import Quota, ack_path, acked_seq, black_boxes, rotated_logs
from monitor.live.writer import DiskWriter

T0 = 1_700_000_000.0


def _mount_error() -> str | None:
    if os.geteuid() != 0:
        return "mounting a tmpfs needs root"
    probe = Path("/tmp") / f"monitor-tmpfs-probe-{os.getpid()}"
    probe.mkdir(exist_ok=True)
    try:
        r = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(probe)],
            capture_output=True,
            text=True,
        )
        if r.returncode:
            return f"cannot mount a tmpfs here: {r.stderr.strip()}"
        subprocess.run(["umount", str(probe)], check=True)
        return None
    finally:
        probe.rmdir()


MOUNT_ERROR = _mount_error()
needs_tmpfs = pytest.mark.skipif(MOUNT_ERROR is not None, reason=str(MOUNT_ERROR))


@pytest.fixture
def small_disk(tmp_path) -> Iterator[Path]:
    """A 1 MB tmpfs of its own."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)], check=True)
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=True)


def _fill(path: Path) -> int:
    """Write zeros to ``path`` until the disk is full; the bytes written."""
    n = 0
    with path.open("wb", buffering=0) as fh:
        try:
            while True:
                n += fh.write(b"\0" * 4096)
        except OSError as exc:
            assert exc.errno == errno.ENOSPC
    return n


def _event(i: int) -> dict:
    # Alarms and normals in turn, each about 300 bytes like the daemon's lines.
    fault = i % 2 == 1
    return {
        "t": i * 1.5,
        "state": "fault" if fault else "normal",
        "J": 0.01,
        "threshold": 0.0012,
        "fault": "spool_wear" if fault else None,
        "pad": "x" * 200,
    }


def _frame100(i: int) -> can.Message:
    """Frame ``i`` of a 100 Hz bus from T0."""
    return can.Message(
        timestamp=T0 + i * 0.01, arbitration_id=0x123, is_extended_id=False, data=bytes(8)
    )


def _lines(*paths: Path) -> list[dict]:
    """Every line of the files, each one whole JSON (a torn line fails the test)."""
    return [json.loads(line) for p in paths for line in p.read_bytes().splitlines()]


@needs_tmpfs
def test_full_disk_deletes_black_boxes_before_losing_an_event(small_disk) -> None:
    """Black boxes filled the disk; 56 events still all land, in order, whole."""
    boxes = small_disk / "blackbox"
    boxes.mkdir()
    for k in range(3):  # three black boxes of about a third of the disk each
        (boxes / f"alarm-2026010{k}T000000.000000Z-spool_wear.log").write_bytes(b"x" * 345_000)
    ev = small_disk / "events.jsonl"
    log = EventLog(ev, quota=Quota(10**9, boxes, ev))
    for i in range(56):
        log.write(log.stamp(_event(i)))
    log.close()
    assert log.unwritten == 0 and log.lost == 0
    assert [e["seq"] for e in _lines(ev)] == list(range(1, 57))
    assert len(list(boxes.glob("alarm-*.log"))) < 3  # boxes gave way, oldest first
    assert log.quota.deleted_black_boxes >= 1


@needs_tmpfs
def test_full_disk_deletes_no_black_box_on_another_filesystem(small_disk, tmp_path) -> None:
    """The event log's disk is full of someone else's file; the black boxes sit on another
    filesystem: deleting them frees nothing there, so they stay and the event waits."""
    boxes = tmp_path / "bb"  # tmp_path is not the tmpfs
    boxes.mkdir()
    for k in range(3):
        (boxes / f"alarm-2026010{k}T000000.000000Z-spool_wear-seq{k + 1}.log").write_text("x")
    ev = small_disk / "events.jsonl"
    log = EventLog(ev, quota=Quota(10**9, boxes, ev))
    log.write(log.stamp(_event(0)))
    filler = small_disk / "someone-elses-file"
    _fill(filler)
    for i in range(1, 40):  # the log's last page fills, then the disk refuses
        log.write(log.stamp(_event(i)))
    assert log.unwritten > 0  # waits in memory: the disk is still full
    assert len(black_boxes(boxes)) == 3 and log.quota.deleted_black_boxes == 0
    filler.unlink()
    log.close()
    assert [e["seq"] for e in _lines(ev)] == list(range(1, 41))


@needs_tmpfs
def test_full_disk_keeps_the_box_being_recorded_and_the_newest(small_disk) -> None:
    """Boxes and event log on one full disk: older boxes give way, the one being recorded
    (the newest alarm's) never does."""
    boxes = small_disk / "bb"
    boxes.mkdir()
    for k in range(2):  # two old boxes of about a third of the disk each
        (boxes / f"alarm-2026010{k}T000000.000000Z-spool_wear-seq{k + 1}.log").write_bytes(
            b"x" * 300_000
        )
    ev = small_disk / "events.jsonl"
    quota = Quota(10**9, boxes, ev)
    log = EventLog(ev, quota=quota)
    box = BlackBox(BlackBoxConfig(directory=boxes, pre_s=1.0, post_s=60.0), quota=quota)
    for i in range(100):
        box.add(_frame100(i))
    recording = box.trigger(T0 + 1.0, "piston_wear", seq=3)
    _fill(small_disk / "filler")  # the disk is full while the box is being written
    for i in range(3):
        log.write(log.stamp(_event(i)))
    assert log.unwritten == 0 and quota.deleted_black_boxes >= 1
    assert recording.exists()  # the box being recorded survived make_room
    assert recording in black_boxes(boxes)
    box.close()
    log.close()


@needs_tmpfs
def test_full_disk_keeps_events_in_memory_and_writes_them_when_room_returns(small_disk) -> None:
    ev = small_disk / "events.jsonl"
    log = EventLog(ev, quota=Quota(10**9, small_disk / "bb", ev))
    for i in range(5):
        log.write(log.stamp(_event(i)))
    filler = small_disk / "someone-elses-file"
    _fill(filler)  # nothing of ours to delete: the events must wait
    for i in range(5, 40):
        log.write(log.stamp(_event(i)))
    assert log.unwritten > 0 and log.disk_errors > 0
    assert [e["seq"] for e in _lines(ev)] == list(range(1, 41 - log.unwritten))  # no torn line
    assert not log.retry()  # still full
    filler.unlink()
    assert log.retry()
    log.close()
    assert [e["seq"] for e in _lines(ev)] == list(range(1, 41))
    assert int(seq_path(ev).read_text()) == 40


@needs_tmpfs
def test_close_on_a_full_disk_says_what_is_unwritten(small_disk) -> None:
    ev = small_disk / "events.jsonl"
    log = EventLog(ev)
    _fill(small_disk / "filler")
    for i in range(3):
        log.write(log.stamp(_event(i)))
    log.close()
    assert log.unwritten == 3  # the daemon's stop reports these and exits non-zero


def test_failed_rotation_writes_on_in_the_current_file(tmp_path, monkeypatch) -> None:
    """The directory refuses renames (an immutable directory): no event lost, no
    exception, the rotation done at the next event once renames work again."""
    ev = tmp_path / "ev.jsonl"
    log = EventLog(ev, rotate_bytes=1000)
    real_rename = Path.rename

    def refuse(self: Path, target: Path) -> Path:
        raise PermissionError(errno.EPERM, "Operation not permitted", str(self))

    monkeypatch.setattr(Path, "rename", refuse)
    for i in range(10):  # ~3 KB: three rotations refused
        log.write(log.stamp(_event(i)))
    assert log.rotations == 0 and log.disk_errors >= 1 and log.unwritten == 0
    monkeypatch.setattr(Path, "rename", real_rename)
    log.write(log.stamp(_event(10)))
    log.close()
    assert log.rotations == 1
    assert [e["seq"] for e in _lines(*rotated_logs(ev), ev)] == list(range(1, 12))


def test_seq_survives_a_moved_log_and_a_garbage_tail(tmp_path) -> None:
    ev = tmp_path / "ev.jsonl"
    log = EventLog(ev, rotate_bytes=700)
    for i in range(9):
        log.write(log.stamp(_event(i)))
    log.close()
    for p in [*rotated_logs(ev), ev]:  # the uploader took everything away
        p.rename(tmp_path / f"uploaded-{p.name}")
    log = EventLog(ev, rotate_bytes=700)
    assert log.last_seq == 9
    log.write(log.stamp(_event(9)))
    log.close()
    with ev.open("ab") as fh:  # 70 KB of garbage after the last good line
        fh.write(os.urandom(70_000).replace(b"\n", b"?"))
    log = EventLog(ev, rotate_bytes=10**9)
    assert log.last_seq == 10
    log.close()


def test_a_fifo_at_the_acked_name_blocks_nothing(tmp_path) -> None:
    ev = tmp_path / "ev.jsonl"
    ev.write_text('{"seq": 2, "state": "fault"}\n')
    ev.with_name("ev.jsonl.1").write_text('{"seq": 1, "state": "fault"}\n')
    os.mkfifo(ack_path(ev))
    result: list[int] = []
    t = threading.Thread(target=lambda: result.append(acked_seq(ev)), daemon=True)
    t.start()
    t.join(30)  # a hang detector, not a timing: the read must not wait for a writer
    assert not t.is_alive() and result == [0]  # nothing acknowledged: every alarm kept
    used = Quota(10, tmp_path / "bb", ev).enforce()
    assert ev.with_name("ev.jsonl.1").exists() and used > 10


@pytest.mark.parametrize("acked", ["12\n", "  7 ", "x" * 100_000, "-3", "1e9"])
def test_acked_file_reads_only_a_plain_number(tmp_path, acked: str) -> None:
    ev = tmp_path / "ev.jsonl"
    ack_path(ev).write_text(acked)
    expect = int(acked) if acked.strip().isdigit() else 0
    assert acked_seq(ev) == expect


def test_event_log_refuses_a_planted_link(tmp_path) -> None:
    target = tmp_path / "passwd"
    target.write_text("root:x:0:0\n")
    ev = tmp_path / "logs" / "ev.jsonl"
    ev.parent.mkdir()
    ev.symlink_to(target)
    with pytest.raises(ConfigError, match="event_log.path: cannot open"):
        EventLog(ev)
    assert target.read_text() == "root:x:0:0\n"


def _frames(n: int) -> list[can.Message]:
    return [
        can.Message(
            timestamp=T0 + i * 0.01, arbitration_id=0x123, is_extended_id=False, data=bytes(8)
        )
        for i in range(n)
    ]


def test_black_box_never_writes_through_a_link_nor_over_a_file(tmp_path) -> None:
    target = tmp_path / "precious"
    target.write_text("keep me\n")
    cfg = BlackBoxConfig(directory=tmp_path / "bb", pre_s=1.0, post_s=0.0)
    box = BlackBox(cfg, writer=DiskWriter(inline=True))
    for m in _frames(50):
        box.add(m)
    t_alarm = T0 + 0.49
    planted = box.directory / "alarm-20231114T221320.490000Z-spool_wear.log"
    planted.symlink_to(target)
    first = box.trigger(t_alarm, "spool_wear")
    box.close()
    second = box.trigger(t_alarm, "spool_wear")  # a second loop's alarm at the same instant
    box.close()
    assert first == planted and second != first
    assert target.read_text() == "keep me\n" and planted.is_symlink()
    written = sorted(p for p in box.directory.iterdir() if not p.is_symlink())
    assert len(written) == 2  # both alarms recorded, each in a file of its own
    assert all(len(p.read_text().splitlines()) == 50 for p in written)


def test_a_failing_job_never_ends_the_writer_thread() -> None:
    w = DiskWriter()
    w.start()
    done: list[int] = []

    def broken() -> None:
        raise ValueError("I/O operation on closed file")

    w.put_event(broken)
    w.put_event(lambda: done.append(1))
    assert w.wait_idle(30)
    assert w.alive and done == [1] and w.counts.job_errors == 1
    w.stop()


@needs_tmpfs
def test_daemon_on_a_full_disk_flags_disk_error_and_reports_unwritten(small_disk, tmp_path) -> None:
    """The daemon on a disk that is full: MON_Status says DiskError, the events wait, and
    ``stop`` reports how many could not be written (``monitor run`` exits 1 then)."""
    from live_support import live_config, replay_settled, run_daemon

    from monitor.resources import resource_path

    cfg = live_config(tmp_path)
    cfg = dataclasses.replace(
        cfg,
        event_log=dataclasses.replace(cfg.event_log, path=small_disk / "events.jsonl"),
        black_box=dataclasses.replace(cfg.black_box, directory=small_disk / "bb"),
    )
    _fill(small_disk / "filler")
    daemon, events, frames, _ = run_daemon(
        cfg, replay_settled(resource_path("replay", "spool_wear.log"))
    )
    assert events and daemon.error is None
    assert daemon.unwritten == len(events)  # every event kept, none on disk
    dbc = daemon.codec.message("MON_Status").dbc_message
    status = [dbc.decode(m.data) for m in frames if m.arbitration_id == dbc.frame_id]
    assert status and any(s["DiskError"] == "error" for s in status)


def test_run_exits_1_when_events_could_not_be_written(tmp_path, monkeypatch) -> None:
    """`monitor run`'s ordered stop with events still refused by the disk: exit 1 (a
    service manager then restarts it and the journal says how many), never 0."""
    import argparse
    import signal

    from monitor.cli import run as run_cmd
    from monitor.live import daemon as daemon_module

    class Stopped:  # the daemon's surface that `run` uses; SIGTERM right after the start
        reload_attempts = 0
        loop_mono = 0.0
        healthy = True
        unwritten = 0

        def __init__(self, cfg) -> None:  # noqa: ANN001
            pass

        def start(self) -> None:
            os.kill(os.getpid(), signal.SIGTERM)

        def stop(self) -> None:
            self.unwritten = 3  # what Daemon.stop finds when the event log kept lines

    monkeypatch.setattr(daemon_module, "Daemon", Stopped)
    monkeypatch.setattr("monitor.live.journal.setup_logging", lambda level: None)  # pytest's
    config = tmp_path / "m.yaml"
    config.write_text(f"event_log: {{path: {tmp_path / 'ev.jsonl'}}}\n")
    saved = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)}
    try:
        code = run_cmd.run(argparse.Namespace(config=config, verbose=False))
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    assert code == 1
