"""The monitor's own frames stay under ``outputs.frames_max_per_s`` whatever comes in: a
flood of J1939 requests beside the sensor frames, sent as fast as the bus takes them.

The bound checked over the daemon's whole run is the rate cap's own invariant (a run slowed by
a busy machine only loosens it): frames sent <= rate x run time + one second's worth; the
cap itself holds exactly over every one-second window (by hand, and in the daemon on a
stepped clock).
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from types import SimpleNamespace

import can
import numpy as np
from live_support import drain, live_config, settle, wait_until

from monitor.io.candump import read_candump
from monitor.live.daemon import Daemon
from monitor.live.ratecap import RateCap
from monitor.resources import resource_path

DM1_REQUEST = can.Message(arbitration_id=0x18EAA0F9, data=b"\xca\xfe\x00")  # DM1 from 0xF9
DM2_REQUEST = can.Message(arbitration_id=0x18EAFFF9, data=b"\xcb\xfe\x00")  # DM2 to all


def test_rate_cap_counted_by_hand() -> None:
    b = RateCap(2.0)  # at most 2 in any one-second window
    assert [b.take(0.0) for _ in range(3)] == [True, True, False]
    assert b.take(0.5) is False  # 0.0 and 0.0 still within the window
    assert b.take(1.0) is True  # both left it
    assert b.take(1.5) is True  # only 1.0 within the window: one more fits
    assert b.take(1.6) is False
    assert [b.take(2.0), b.take(2.0)] == [True, False]  # 1.0 left, 1.5 still in
    assert [b.take(3.0), b.take(3.0), b.take(3.0)] == [True, True, False]


def test_rate_cap_holds_over_every_one_second_window() -> None:
    """The 50 frames/s cap let 60 frames out in one second: a bucket's burst of 50, then
    what refilled.  Offered a frame every 5 ms for 5 s, no window of 1 s holds more than
    50, and the cap is not stricter than that (50 in the first second)."""
    cap = RateCap(50.0)
    t = np.arange(0, 1000) * 0.005
    sent = np.array([x for x in t if cap.take(float(x))])
    for start in sent:  # the worst windows start at a frame sent
        assert np.sum((sent >= start) & (sent < start + 1.0)) <= 50
    assert np.sum(sent < 1.0) == 50 and len(sent) == 250


def test_rate_cap_below_one_per_second_and_long_messages() -> None:
    slow = RateCap(0.5)  # one frame in any 2 s
    assert [slow.take(x) for x in (0.0, 1.9, 2.0, 3.0)] == [True, False, True, False]
    cap = RateCap(4.0)
    assert cap.take(0.0, 6)  # a message larger than the cap goes out alone...
    assert not cap.take(0.9, 1)
    assert cap.take(1.0, 3) and not cap.take(1.5, 2)  # ...and only into an empty window


def test_daemon_cap_is_exact_over_a_second(tmp_path, monkeypatch) -> None:
    """The daemon's own cap on every frame it sends (``outputs.frames_max_per_s`` 50), its
    wall clock replaced by one stepped 5 ms per frame offered: at most 50 in any second."""
    cfg = live_config(tmp_path)
    cfg = dataclasses.replace(cfg, outputs=dataclasses.replace(cfg.outputs, frames_max_per_s=50.0))
    listener = can.Bus(interface="virtual", channel=cfg.bus.channel)
    daemon = Daemon(cfg)
    clock = {"t": 1000.0}
    monkeypatch.setattr(
        "monitor.live.transmit.time", SimpleNamespace(monotonic=lambda: clock["t"], time=time.time)
    )
    sent = []
    try:
        for i in range(600):
            clock["t"] = 1000.0 + i * 0.005
            capped = daemon.tx.capped
            daemon.tx.send(can.Message(arbitration_id=0x18FF00A0, data=bytes(8)))
            if daemon.tx.capped == capped:
                sent.append(clock["t"])
    finally:
        monkeypatch.undo()
        daemon.stop()
    t = np.array(sent)
    assert len(drain(listener)) == len(t)
    assert max(np.sum((t >= s) & (t < s + 1.0)) for s in t) == 50


def test_a_request_flood_never_makes_the_monitor_flood_the_bus(tmp_path) -> None:
    cfg = live_config(tmp_path)
    cfg = dataclasses.replace(cfg, outputs=dataclasses.replace(cfg.outputs, frames_max_per_s=5.0))
    msgs = list(itertools.islice(read_candump(resource_path("replay", "spool_wear.log")), 9000))
    listener = can.Bus(interface="virtual", channel=cfg.bus.channel)
    daemon = Daemon(cfg)
    start = time.monotonic()
    with can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True) as tx:
        daemon.start()
        try:
            sent = 0
            for m in msgs:
                for x in (m, DM1_REQUEST, DM2_REQUEST):
                    x.channel = None
                    tx.send(x)
                    sent += 1
            wait_until(lambda: daemon.reader.counts.received >= sent)
            settle(daemon, len(msgs))  # the sensor frames decoded
        finally:
            daemon.stop()
    elapsed = time.monotonic() - start
    ours = [m for m in drain(listener) if m.arbitration_id & 0xFF == 0xA0]
    assert daemon.counts()["j1939_requests"] >= 1000  # the flood reached the monitor
    assert daemon.tx.capped > 0
    assert len(ours) <= 5.0 * elapsed + 5
