"""The disk writer: jobs run in order in its own thread; a full queue drops black-box work
with a count and never loses an event; stop drains.  The black box writes the same frames
through the writer as synchronously."""

from __future__ import annotations

import threading
from pathlib import Path

import can
import pytest

from monitor.config.settings import BlackBoxConfig
from monitor.io.candump import read_candump
from monitor.live.blackbox import BATCH_FRAMES, BlackBox
from monitor.live.writer import DiskWriter

T0 = 1_700_000_000.0
DT = 1 / 64  # exact in binary: the window edges are exact comparisons


@pytest.fixture
def writer():
    w = DiskWriter(capacity=4, event_block_s=0.01)
    w.start()
    yield w
    w.stop()


def _blocked(w: DiskWriter) -> threading.Event:
    """Occupy the writer's thread until the returned event is set."""
    go, running = threading.Event(), threading.Event()

    def hold() -> None:
        running.set()
        go.wait(30)

    w.put_event(hold)
    assert running.wait(30)
    return go


def test_jobs_run_in_order_in_the_writer_thread(writer) -> None:
    done: list[tuple[int, str]] = []
    for i in range(10):
        writer.put_event(lambda i=i: done.append((i, threading.current_thread().name)))
    assert writer.wait_idle(30)
    assert done == [(i, "disk-writer") for i in range(10)]


def test_full_queue_drops_frames_with_a_count_and_keeps_events(writer) -> None:
    go = _blocked(writer)
    done: list[str] = []
    for i in range(4):  # capacity 4: the queue is now full
        assert writer.put_frames(lambda i=i: done.append(f"frames{i}"), 10)
    assert not writer.put_frames(lambda: done.append("lost"), 7)
    writer.put_event(lambda: done.append("event"))  # waits 0.01 s, then queued anyway
    go.set()
    assert writer.stop(30)
    assert done == ["frames0", "frames1", "frames2", "frames3", "event"]
    c = writer.counts
    assert (c.frames_dropped, c.events_over_bound, c.max_depth) == (7, 1, 5)


def test_stop_drains_and_later_jobs_run_in_the_caller(writer) -> None:
    go = _blocked(writer)
    done: list[str] = []
    writer.put_event(lambda: done.append(threading.current_thread().name))
    go.set()
    assert writer.stop(30) and done == ["disk-writer"]
    writer.put_event(lambda: done.append(threading.current_thread().name))
    assert done == ["disk-writer", threading.current_thread().name]


def test_a_failing_write_is_counted_and_the_next_ones_run(writer) -> None:
    done: list[int] = []

    def fail() -> None:
        raise OSError(28, "No space left on device")

    writer.put_event(fail)
    writer.put_event(lambda: done.append(1))
    assert writer.wait_idle(30)
    assert done == [1] and writer.counts.job_errors == 1


def _frame(i: int) -> can.Message:
    return can.Message(
        timestamp=T0 + i * DT, arbitration_id=0x100 + i % 3, data=bytes([i % 256]) * 8
    )


def _record(directory: Path, writer: DiskWriter | None) -> list[Path]:
    """Alarms at frames 100 and 700; pre 0.5 s (32 frames), post 5 s (320 frames)."""
    box = BlackBox(BlackBoxConfig(directory=directory, pre_s=0.5, post_s=5.0), writer=writer)
    for i in range(1100):
        box.add(_frame(i))
        if i in (100, 700):
            box.trigger(T0 + i * DT, "spool_wear")
    box.close()
    if writer is not None:
        assert writer.stop(30)
    return sorted(directory.glob("alarm-*.log"))


def test_black_box_through_the_writer_holds_exactly_the_window(tmp_path) -> None:
    threaded = DiskWriter()
    threaded.start()
    files = _record(tmp_path / "thread", threaded)
    inline = _record(tmp_path / "inline", None)
    assert [p.read_bytes() for p in files] == [p.read_bytes() for p in inline]
    # From 0.5 s before each alarm (frame k - 32) to 5 s after it (k + 320), both included;
    # 320 post-alarm frames go over in batches (the last one partial).
    assert 320 % BATCH_FRAMES != 0
    for path, k in zip(files, (100, 700), strict=True):
        got = [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in read_candump(path)]
        want = [(T0 + i * DT, 0x100 + i % 3, bytes([i % 256]) * 8) for i in range(k - 32, k + 321)]
        assert got == want
    assert threaded.counts.frames_dropped == 0


def test_a_dropped_black_box_start_never_spills_into_the_previous_file(tmp_path) -> None:
    w = DiskWriter(capacity=10)
    w.start()
    cfg = BlackBoxConfig(directory=tmp_path, pre_s=0.5, post_s=1.0)
    box = BlackBox(cfg, writer=w)
    for i in range(101):
        box.add(_frame(i))
    first = box.trigger(T0 + 100 * DT, "a")  # frames 68..100 queued
    assert w.wait_idle(30)
    go = _blocked(w)
    while w.put_frames(lambda: None, 0):  # fill the queue
        pass
    second = box.trigger(T0 + 100 * DT + 0.001, "b")  # the close of "a" waits, "b" dropped
    go.set()
    assert w.wait_idle(30)
    for i in range(101, 200):
        box.add(_frame(i))  # the post-alarm frames of "b": no file to go to
    box.close()
    assert w.stop(30)
    assert not second.exists()
    assert len(list(read_candump(first))) == 33  # only its own pre-alarm frames
    assert w.counts.frames_dropped == 33 + 64  # b's 33 pre-alarm and 64 post-alarm frames
