"""The monitor's own frames stay under ``outputs.frames_max_per_s`` whatever comes in: a
flood of J1939 requests beside the sensor frames, sent as fast as the bus takes them.

The bound checked is the token bucket's own invariant over the daemon's whole run (a run
slowed by a busy machine only loosens it): frames sent <= rate x run time + one second's
burst.
"""

from __future__ import annotations

import dataclasses
import itertools
import time

import can
from live_support import drain, live_config, settle, wait_until

from monitor.io.candump import read_candump
from monitor.live.daemon import Daemon
from monitor.live.outputs import TokenBucket
from monitor.resources import resource_path

DM1_REQUEST = can.Message(arbitration_id=0x18EAA0F9, data=b"\xca\xfe\x00")  # DM1 from 0xF9
DM2_REQUEST = can.Message(arbitration_id=0x18EAFFF9, data=b"\xcb\xfe\x00")  # DM2 to all


def test_token_bucket_counted_by_hand() -> None:
    b = TokenBucket(2.0)  # 2 per second, bursts of 2
    assert [b.take(0.0) for _ in range(3)] == [True, True, False]
    assert b.take(0.4) is False  # 0.8 token
    assert b.take(0.5) is True  # 1.0 token
    assert [b.take(10.0) for _ in range(3)] == [True, True, False]  # refilled to 2, no more


def test_a_request_flood_never_makes_the_monitor_flood_the_bus(tmp_path) -> None:
    cfg = live_config(tmp_path)
    cfg = dataclasses.replace(cfg, outputs=dataclasses.replace(cfg.outputs,
                                                               frames_max_per_s=5.0))
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
    assert daemon.tx_capped > 0
    assert len(ours) <= 5.0 * elapsed + 5
