"""The daemon's ``detector`` thread: the loop that takes the reader's frames in arrival order
and does everything else between them (``monitor.live.daemon``).

One pass: a reload point, then either a frame and the burst queued behind it, or, with
none waiting for 50 ms, the silence check; then MON_Status and the bus events.  Once stopped
(the reader is stopped first, so nothing more is queued) it drains the queue and ends with
the work's ``finish``.  ``loop_mono`` is the last pass's monotonic time (the watchdog's);
an exception ends the thread and is kept in ``error`` (``healthy`` in the daemon).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Protocol

import can

log = logging.getLogger("monitor")

_BURST = 1000  # frames taken without a timeout per pass


class DetectorWork(Protocol):
    """What the detector thread does (the daemon)."""

    def reload_point(self) -> None: ...

    def frame(self, msg: can.Message) -> None: ...

    def idle(self) -> None: ...

    def beat(self) -> None: ...

    def bus_events(self) -> None: ...

    def finish(self) -> None: ...


class DetectorThread:
    def __init__(self, frames: queue.Queue[can.Message], work: DetectorWork) -> None:
        self.frames = frames
        self.work = work
        self.loop_mono = time.monotonic()  # last pass of the detector loop (watchdog)
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="detector", daemon=True)

    def start(self) -> None:
        self._thread.start()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def stop(self, timeout_s: float) -> None:
        """Drain the queue and end (call it after the reader stopped)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # surfaced by ``healthy``; the supervisor exits
            self.error = exc
            log.exception("detector thread failed")

    def _loop(self) -> None:
        q, work = self.frames, self.work
        while True:
            self.loop_mono = time.monotonic()
            work.reload_point()
            try:
                msg = q.get(timeout=0.05)
            except queue.Empty:
                if self._stop.is_set():
                    break  # the reader is stopped first, so the queue is drained
                work.idle()
            else:
                work.frame(msg)
                self._burst()
            work.beat()
            work.bus_events()
        work.finish()

    def _burst(self) -> None:
        """The frames queued behind the first, without a timeout per frame."""
        for _ in range(_BURST):
            try:
                self.work.frame(self.frames.get_nowait())
            except queue.Empty:
                break
            # A backlog (slow CPU, a flood) must not stall the heartbeat or make the
            # watchdog think the loop is stuck.
            self.work.beat()
            self.loop_mono = time.monotonic()
