"""Put a candump log's frames on a bus with the log's timing, like canplayer.

Frames go out at their log time divided by ``speed`` (``None``: as fast as the bus takes
them).  The frame timestamps are kept in the messages, so a ``virtual`` bus (which keeps
the sender's timestamps) carries the log's own clock at any speed.  Time that jumps
backwards in the log re-anchors the timing at that frame instead of stalling or bursting.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import can

from monitor.errors import BusError, ConfigError
from monitor.io.candump import read_candump


@dataclass
class ReplayCounts:
    sent: int = 0
    send_errors: int = 0
    time_jumps_back: int = 0
    first_ts: float | None = None
    last_ts: float | None = None


def replay_log(
    path: str | Path,
    bus: can.BusABC,
    speed: float | None = 1.0,
    stop: threading.Event | None = None,
    on_frame: Callable[[can.Message, ReplayCounts], None] | None = None,
) -> ReplayCounts:
    """Send every frame of the log; a malformed line raises ``InputFileError`` (file:line)."""
    if speed is not None and not speed > 0:
        raise ConfigError(f"--speed must be > 0, got {speed}")
    counts = ReplayCounts()
    anchor_wall = anchor_ts = 0.0
    newest = -float("inf")
    failing_since: float | None = None
    for msg in read_candump(path):
        if stop is not None and stop.is_set():
            break
        ts = msg.timestamp
        if counts.first_ts is None:
            counts.first_ts = ts
            anchor_wall, anchor_ts = time.monotonic(), ts
        elif ts < newest - 1e-6:
            counts.time_jumps_back += 1
            anchor_wall, anchor_ts = time.monotonic(), ts
        newest = max(newest, ts)
        if speed is not None:
            delay = anchor_wall + (ts - anchor_ts) / speed - time.monotonic()
            if delay > 0:
                if stop is not None:
                    if stop.wait(delay):
                        break
                else:
                    time.sleep(delay)
        msg.channel = None  # the log's interface name must not pick the outgoing interface
        msg.is_rx = False
        try:
            bus.send(msg, timeout=0.1)
            counts.sent += 1
            failing_since = None
        except (can.CanError, OSError) as exc:
            counts.send_errors += 1
            now = time.monotonic()
            failing_since = failing_since or now
            if now - failing_since > 5.0:
                raise BusError(f"cannot send on the bus for 5 s: {exc}") from None
        counts.last_ts = ts
        if on_frame is not None:
            on_frame(msg, counts)
    return counts
