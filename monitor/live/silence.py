"""When the sensors are silent, proven: the frame pipeline's sample clock runs on by proven
silence only (``monitor.live.pipeline``).  Silence is decided from the data, never from a
thread that got no CPU for a while:

* any other frame (a foreign ID, a rejected frame) whose timestamp lies ``bus.silent_s``
  past the last sensor frame proves the sensors silent up to it: the clock runs on to it,
  but never further than the reader's own clock saw pass since that sensor frame (a
  sender's timestamps are not trusted beyond the reader's clock);
* with no frame at all, only the reader can prove silence: ``heard_until`` is the start of
  its latest receive that found nothing (every frame that arrived before is queued), and
  ``received_at`` the moment it received its latest frame (stamped by the reader thread at
  receive time, so no later than the last sensor frame's).  When the first lies
  ``bus.silent_s`` past the second, and nothing waits in the queue, the clock runs on by that
  proven time.  Both are the reader's own clock readings: a backlog in the queue, or a
  detector thread starved of CPU, proves nothing and never makes the monitor inactive.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class SilenceProof:
    """What proves the sensors silent: the last sensor frame's sample-clock time and its
    receive stamp, against a later frame's timestamp or the reader's empty receives.

    ``heard_until``, ``backlog`` and ``received_at`` are the reader's (``BusReader``); with
    ``received_at`` None (no reader) frames are stamped here, on this host's monotonic
    clock.  Times on the sample clock run ``time_scale`` times slower than the bus's."""

    def __init__(
        self,
        silent_s: float,
        time_scale: float,
        heard_until: Callable[[], float],
        backlog: Callable[[], bool],
        received_at: Callable[[], float] | None,
    ) -> None:
        self.silent_s = silent_s
        self._scale = time_scale
        self._heard_until = heard_until
        self._backlog = backlog
        self._received_at = received_at
        self.last_ok_ts = 0.0  # sample-clock time of the last sensor frame
        self._last_ok_mono = time.monotonic()  # its wall time (no reader)
        self._last_ok_rx = -float("inf")  # the reader's receive stamp by then

    def sensor_frame(self, ts: float) -> None:
        """A sensor frame at sample-clock time ``ts`` was taken."""
        if self._received_at is None:
            self._last_ok_mono = time.monotonic()
        else:
            self._last_ok_rx = self._received_at()
        self.last_ok_ts = ts

    def idle_before(self, ts: float) -> float:
        """Sample seconds a frame at sample-clock time ``ts`` (not a sensor frame) proves
        silent since the last sensor frame."""
        idle = ts - self.last_ok_ts
        if self._received_at is not None:
            # A sender's timestamp proves no more time than the reader's own clock saw
            # pass: a flood stamped ahead must not run the sample clock on.
            idle = min(idle, (self._received_at() - self._last_ok_rx) / self._scale)
        return idle

    def idle_heard(self) -> float:
        """Sample seconds the reader's empty receives prove silent (-inf: none, frames wait)."""
        heard = self._heard_until()  # read before the queue: a frame queued later is pending
        if self._backlog():
            return -float("inf")
        # Read after the queue: a frame that came in since is later than ``heard``: no proof.
        last = self._last_ok_mono if self._received_at is None else self._received_at()
        return (heard - last) / self._scale

    def silent(self, idle_s: float) -> bool:
        """Whether ``idle_s`` sample seconds without a sensor frame are a silence."""
        return idle_s >= self.silent_s / self._scale
