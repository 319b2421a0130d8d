"""Black-box retention by the alarm's ``seq``, not by the clock in a name: ``max_files`` and
the quota keep the newest alarm's box (the full-disk cases are in test_disk_faults)."""

from __future__ import annotations

import can
import pytest
from test_disk_faults import T0

from monitor.config.settings import BlackBoxConfig
from monitor.live.blackbox import BlackBox
from monitor.live.storage import Quota, black_boxes, box_seq


def _frame(i: int) -> can.Message:
    return can.Message(
        timestamp=T0 + i * 0.01, arbitration_id=0x123, is_extended_id=False, data=bytes(8)
    )


def test_max_files_keeps_the_new_alarm_although_older_names_run_ahead(tmp_path) -> None:
    """Boxes of earlier alarms named by a clock that ran ahead (2031): the new alarm's box,
    named 2026 but the highest seq, is kept, and the oldest by seq goes."""
    d = tmp_path / "bb"
    d.mkdir()
    old = [d / f"alarm-2031010{k}T000000.000000Z-spool_wear-seq{k + 1}.log" for k in range(3)]
    for p in old:
        p.write_text("x\n")
    box = BlackBox(BlackBoxConfig(directory=d, pre_s=0.5, post_s=0.1, max_files=3))
    for i in range(60):
        box.add(_frame(i))
    new = box.trigger(T0 + 0.5, "piston_wear", seq=4)
    box.close()
    assert new.exists()
    assert black_boxes(d) == [*old[1:], new]
    assert [box_seq(p) for p in black_boxes(d)] == [2, 3, 4]


def test_quota_keeps_the_newest_alarm_box(tmp_path) -> None:
    d = tmp_path / "bb"
    d.mkdir()
    names = [
        "alarm-20310101T000000.000000Z-a-seq7.log",  # clock ahead, but older
        "alarm-20260101T000000.000000Z-b-seq9.log",
        "alarm-20260101T000000.000000Z-c.log",
    ]  # a name of an earlier release: oldest
    for n in names:
        (d / n).write_text("x" * 1000)
    q = Quota(500, d, tmp_path / "ev.jsonl")
    assert q.enforce() == 1000  # over the quota rather than the newest alarm's box deleted
    assert [p.name for p in q.black_boxes()] == [names[1]]


@pytest.mark.parametrize(
    ("name", "seq"),
    [
        ("alarm-20260101T000000.000000Z-piston_wear-seq12.log", 12),
        ("alarm-20260101T000000.000000Z-piston_wear-seq12-3.log", 12),
        ("alarm-20260101T000000.000000Z-piston_wear-seq12~1.log", 12),
        ("alarm-20260101T000000.000000Z-boom-piston_wear.log", 0),
    ],
)
def test_box_seq_from_the_name(tmp_path, name: str, seq: int) -> None:
    assert box_seq(tmp_path / name) == seq
