"""Every frame the daemon sends (MON_Alarm, MON_Status, DM1/DM2) leaves through one
``Transmitter``: nothing while the bus is down or bus-off (it would fail, or block for
nothing), never more than ``outputs.frames_max_per_s`` on the wall clock whatever the input
(a flood of requests, a flapping state), and a failed send counted, logged at most every
5 s and reported to the reader (perhaps the only sign the link went down)."""

from __future__ import annotations

import logging
import time

import can

from monitor.bus.reader import BusReader
from monitor.live.ratecap import RateCap

log = logging.getLogger("monitor")

_LOG_EVERY_S = 5.0


class Transmitter:
    """Sends on the reader's bus (the reader replaces it when it reopens a failed one)."""

    def __init__(self, reader: BusReader, frames_max_per_s: float, time_scale: float) -> None:
        self.reader = reader
        self.frames_max_per_s = frames_max_per_s
        # A log replayed faster than real time (time_scale < 1) times its alarms faster too.
        self._budget = RateCap(frames_max_per_s / min(1.0, time_scale))
        self.errors = 0  # sends that failed, or were not tried with the bus down
        self.capped = 0  # own frames dropped by outputs.frames_max_per_s
        self._last_cap_log = 0.0
        self._last_error_log = 0.0

    def send(self, msg: can.Message) -> None:
        if not self.reader.bus_up:
            self.errors += 1
            return
        if not self._budget.take(time.monotonic()):
            self.capped += 1
            now = time.monotonic()
            if now - self._last_cap_log > _LOG_EVERY_S:
                self._last_cap_log = now
                log.error(
                    "own frames over outputs.frames_max_per_s (%g/s): %d dropped so far",
                    self.frames_max_per_s,
                    self.capped,
                )
            return
        try:
            self.reader.bus.send(msg, timeout=0.05)
        except (can.CanError, OSError) as exc:
            self.errors += 1
            self.reader.report_send_error(exc)
            now = time.monotonic()
            if now - self._last_error_log > _LOG_EVERY_S:
                self._last_error_log = now
                log.error(
                    "cannot send %X (%s); %d send errors", msg.arbitration_id, exc, self.errors
                )
