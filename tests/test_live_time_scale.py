"""``bus.time_scale``: a log replayed k times slower than real time onto a bus gives the
same events, in log seconds, as the log itself at desk (``monitor detect``)."""

from __future__ import annotations

from typing import Any

import can
from live_support import assert_same_events, live_config, send_all, settle
from naive_frames import recording_from_candump

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.io.candump import read_candump
from monitor.live.daemon import Daemon
from monitor.model.modelfile import load_model
from monitor.resources import resource_path

LOG = resource_path("replay", "spool_wear.log")
SLOWER = 4.0


def test_slowed_replay_gives_the_events_of_the_log(tmp_path) -> None:
    cfg = live_config(tmp_path, time_scale=SLOWER)
    msgs = list(read_candump(LOG))
    t0 = msgs[0].timestamp
    for m in msgs:  # what the bus timestamps of a 4x slower replay look like
        m.timestamp = t0 + (m.timestamp - t0) * SLOWER
    events: list[dict[str, Any]] = []
    daemon = Daemon(cfg, on_event=events.append)
    daemon.start()
    try:
        with can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True) as tx:
            settle(daemon, send_all(tx, msgs))
    finally:
        daemon.stop()
    shipped = load_config()
    offline = detect(
        load_model(shipped.model), recording_from_candump(LOG), shipped.alarm, shipped.horizon
    )
    assert any(e["state"] == "fault" for e in offline.events)
    assert_same_events(events, offline)
