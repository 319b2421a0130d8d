"""What `monitor fleet run` shows on stderr while it works.

On a terminal one status line redrawn in place (logs done, machines commissioned, rate, time
left), with messages printed above it; elsewhere (a log file, CI, cron) the messages and a
status line every ``every_s`` seconds, as a long batch job prints, never carriage returns.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TextIO


def _duration(s: float) -> str:
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


class Progress:
    """Counts of a fleet run and their display; ``say`` prints one message."""

    def __init__(
        self,
        stream: TextIO,
        tty: bool,
        every_s: float = 30.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.stream, self.tty, self.every_s, self.clock = stream, tty, every_s, clock
        self.start = self.clock()
        self._last = self.start  # when the status was last shown
        self._drawn = False  # a status line is on the terminal, to be cleared before a message
        self.logs_total = self.logs_done = self.frames = 0
        self.machines_total = self.machines_done = 0
        self._judging_since: float | None = None
        # What is counted: logs and machines, or (whole machines) each loop of them.
        self.log_unit, self.model_unit = "logs", "machines"

    def per_loop(self) -> None:
        """Count every loop of a whole machine: a log judged per loop, a model per loop."""
        self.log_unit, self.model_unit = "log loops", "loop models"

    # --- counts -----------------------------------------------------------------------
    def commissioning(self, machines: int) -> None:
        self.machines_total = machines
        self.refresh(force=True)

    def commissioned(self) -> None:
        self.machines_done += 1
        self.refresh(force=True)

    def judging(self, logs: int) -> None:
        self.logs_total = logs
        self._judging_since = self.clock()
        self.refresh(force=True)

    def judged(self, frames: int | None) -> None:
        self.logs_done += 1
        self.frames += frames or 0
        self.refresh()

    # --- display ----------------------------------------------------------------------
    def status(self) -> str:
        now = self.clock()
        parts = []
        if self._judging_since is not None:
            parts.append(f"{self.logs_done}/{self.logs_total} {self.log_unit}")
        if self.machines_total:
            parts.append(
                f"{self.machines_done}/{self.machines_total} {self.model_unit} commissioned"
            )
        since = self._judging_since
        if since is not None and self.logs_done and now > since:
            rate = self.logs_done / (now - since)
            fps = self.frames / (now - since)
            parts.append(f"{rate:.2f} {self.log_unit}/s, {fps:,.0f} frames/s")
            if self.logs_done < self.logs_total:
                parts.append(f"about {_duration((self.logs_total - self.logs_done) / rate)} left")
        parts.append(f"{_duration(now - self.start)} elapsed")
        return "fleet: " + ", ".join(parts)

    def refresh(self, force: bool = False) -> None:
        """Show the status if it is due: a terminal twice a second, else every ``every_s``."""
        now = self.clock()
        if not force and now - self._last < (0.5 if self.tty else self.every_s):
            return
        if not self.tty and force and now - self._last < self.every_s:
            return  # a log file gets periodic lines only, not one per machine
        self._last = now
        self._show(self.status())

    def say(self, message: str) -> None:
        self._clear()
        print(message, file=self.stream, flush=True)
        if self.tty and (self.logs_total or self.machines_total):
            self._show(self.status())

    def close(self) -> None:
        """The final status as a line of its own (on a terminal, the redrawn one kept)."""
        self._clear()
        print(self.status(), file=self.stream, flush=True)

    def end(self) -> None:
        """Clear a status line still drawn (before an error line, say)."""
        self._clear()

    def _show(self, line: str) -> None:
        if self.tty:
            self.stream.write("\r" + line + "\x1b[K")
            self.stream.flush()
            self._drawn = True
        else:
            print(line, file=self.stream, flush=True)

    def _clear(self) -> None:
        if self._drawn:
            self.stream.write("\r\x1b[K")
            self._drawn = False
