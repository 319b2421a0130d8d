"""One rate cap for every frame the monitor sends: at most ``cap`` frames in any window of
``window_s`` (one second), exactly.

A token bucket holding one second's worth lets twice that through in a second (a full
bucket's burst, then what refills), so a "50 frames/s" cap let 60-100 frames out in one
second.  This keeps the times of the frames sent in the last window instead (at most
``cap`` entries) and lets a frame out only while fewer than ``cap`` lie within it.  The
clock is the caller's: wall (monotonic) time for the daemon's cap on all its frames, the
sample clock for MON_Alarm and the J1939 messages, so a replayed log gives the same frames
at any speed.
"""

from __future__ import annotations

import math
from collections import deque


class RateCap:
    """At most ``rate_per_s`` frames in any one-second window (a rate below 1/s: one frame
    in any ``1 / rate_per_s`` s).  A non-integer rate is rounded down: the cap is a bound."""

    def __init__(self, rate_per_s: float) -> None:
        if not rate_per_s > 0:
            raise ValueError(f"rate_per_s must be > 0, got {rate_per_s}")
        self.rate = float(rate_per_s)
        self.window_s = max(1.0, 1.0 / self.rate)
        self.cap = max(1, math.floor(self.rate * self.window_s + 1e-9))
        self._sent: deque[tuple[float, int]] = deque()  # (time, frames), oldest first
        self._count = 0  # frames in ``_sent``

    def in_window(self, now_s: float) -> int:
        """Frames sent in the window ending at ``now_s`` (older ones forgotten)."""
        sent = self._sent
        while sent and now_s - sent[0][0] >= self.window_s:
            self._count -= sent.popleft()[1]
        return self._count

    def allows(self, now_s: float, n: int = 1) -> bool:
        """Whether ``n`` frames may go out at ``now_s``; a message of more frames than the
        cap goes out alone, once the window is empty."""
        count = self.in_window(now_s)
        return count + n <= self.cap or count == 0

    def record(self, now_s: float, n: int = 1) -> None:
        """``n`` frames went out at ``now_s``."""
        self._sent.append((now_s, n))
        self._count += n

    def take(self, now_s: float, n: int = 1) -> bool:
        """Record ``n`` frames at ``now_s`` if ``allows``; whether it did."""
        if not self.allows(now_s, n):
            return False
        self.record(now_s, n)
        return True
