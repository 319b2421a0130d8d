"""Restarts under attack, on the attack harness (tests/attack_support.py: ``monitor run``,
``monitor replay`` and a sniffer, each a process of its own on a udp_multicast group and
port of their own).

The case of issue 43: the daemon is killed (SIGKILL), the event logs and ``.seq`` are moved
away but ``.acked`` (50) is left; at the restart the numbering went back to 1, so the new
fault counted as acknowledged and the storage quota deleted the log that held it.  Now the
numbering goes on above 50, the fault is unsent and its log and its black box (named by its
seq) survive the quota, and its MON_Alarm frames went out on the bus.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from attack_support import AttackRig, multicast_error

from monitor.codec.frames import FrameCodec
from monitor.detection.alarm import State
from monitor.live.eventlog import seq_path
from monitor.live.storage import ack_path, black_boxes, box_seq
from monitor.resources import resource_path

pytestmark = pytest.mark.skipif(multicast_error() is not None, reason=str(multicast_error()))

LOG = resource_path("replay", "spool_wear.log")  # spool wear raised at 53.02 s of 90 s


def _head(log: Path, seconds: float, out: Path) -> Path:
    """The first ``seconds`` of a candump log."""
    lines = log.read_text().splitlines(keepends=True)
    t0 = float(lines[0][1:].split(")")[0])
    out.write_text("".join(x for x in lines if float(x[1:].split(")")[0]) < t0 + seconds))
    return out


def test_killed_daemon_with_logs_moved_and_acked_left_numbers_on_above_acked(
    tmp_path: Path,
) -> None:
    # Event-log files of two ~400-byte lines, and a quota far below one black box: the
    # quota deletes every rotated file it is allowed to.
    rig = AttackRig(tmp_path, event_log="rotate_mb: 0.001", extra="storage: {quota_mb: 0.0025}\n")
    rig.sniff()
    try:
        rig.start()
        head = _head(LOG, 10.0, tmp_path / "head.log")
        rig.replay(head)
        rig.wait_event(lambda e: e.get("state") == "normal")
        rig.kill()
        first = [e["seq"] for e in rig.events()]
        assert first == list(range(first[0], first[0] + len(first)))
        # The uploader takes the logs and .seq away; its .acked (50) stays behind.
        away = tmp_path / "uploaded"
        away.mkdir()
        for p in [*rig.event_files(), seq_path(rig.events_path)]:
            p.rename(away / p.name)
        ack_path(rig.events_path).write_text("50\n")

        rig.start()
        rig.replay(LOG)
        fault = rig.wait_event(lambda e: e.get("state") == "fault")
        rig.wait_event(lambda e: e["seq"] > fault["seq"] and e.get("state") == "inactive")
        # Three more events (the head again: normal, then inactive when it ends): the
        # fault's file, rotated past 1000 bytes (three lines at most), is then a rotated
        # one, which the quota must keep (unsent); rotation forced by events, not timing.
        rig.replay(head)
        rig.wait_event(lambda e: e["seq"] >= fault["seq"] + 3 and e.get("state") == "inactive")
        assert rig.stop() == 0, (tmp_path / "daemon-2.log").read_text()[-2000:]
    finally:
        if rig.daemon is not None and rig.daemon.poll() is None:
            rig.kill()
        frames = rig.sniffed()
    events = rig.events()
    seqs = [e["seq"] for e in events]
    # Never back, never twice: above 50, one apart.  The oldest rotated files may be gone
    # (a file without an unsent alarm is the quota's to delete), never the fault's.
    assert min(seqs) > 50 and seqs == list(range(seqs[0], seqs[0] + len(seqs))), seqs
    # (Not its name: a replayer starved by the load gives the daemon gaps, and isolation
    # on gappy data is tests/test_live_field.py's subject, not this one's.)
    assert fault["seq"] > 50
    assert fault in events  # its log survived the quota: unsent
    assert fault in events[:-1] and len(rig.event_files()) >= 2  # ... though it was rotated
    # The newest alarm's black box survives the quota, named by the seq of its event.
    boxes = black_boxes(tmp_path / "blackbox")
    alarms = {e["seq"] for e in events if e.get("state") in ("fault", "sensor_fault")}
    assert boxes and {box_seq(p) for p in boxes} <= alarms, (boxes, alarms)
    assert box_seq(boxes[-1]) >= fault["seq"], boxes
    codec = FrameCodec.from_dbc(None)
    states = [codec.decode_message(m) for m in frames if m.arbitration_id & 0xFF == 0xA0]
    alarm_states = {
        int(d.values["State"]) for d in states if d.name == "MON_Alarm" and d.values is not None
    }
    assert int(State.FAULT) in alarm_states  # the fault went out on the bus


def test_sigkills_and_a_stray_rotated_name_never_reuse_a_seq(tmp_path: Path) -> None:
    """Runs each ended by SIGKILL until the event log has rotated twice (an event's size
    varies, so the count of runs is not fixed), a stray ``events.jsonl.01`` planted beside
    the rotated logs: every seq issued once, in order, across the files; the stray file left
    as it was (the rotation used to rename it onto ``.2``, over a rotated log)."""
    rig = AttackRig(tmp_path, event_log="rotate_mb: 0.001")
    stray = tmp_path / "events.jsonl.01"
    stray.write_text('{"seq": 1, "state": "fault", "planted": true}\n')
    head = _head(LOG, 10.0, tmp_path / "head.log")
    last = 0
    try:
        for _ in range(8):
            if len(rig.event_files()) >= 3:
                break
            rig.start()
            rig.replay(head)
            done = last
            rig.wait_event(lambda e, after=done: e["seq"] > after and e.get("state") == "inactive")
            rig.kill()
            last = rig.events()[-1]["seq"]
    finally:
        if rig.daemon is not None and rig.daemon.poll() is None:
            rig.kill()
    seqs = [e["seq"] for e in rig.events()]
    assert seqs == list(range(1, last + 1)) and len(rig.event_files()) >= 3
    assert stray.read_text() == '{"seq": 1, "state": "fault", "planted": true}\n'
