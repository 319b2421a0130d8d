"""The daemon's disk writer: one thread does every write, flush and fsync of the event log
and the black box, fed by a bounded queue, so the detector thread only enqueues.

A state change used to cost the detector thread an fsync of the event log and the dump of up
to ``black_box.max_frames`` pre-alarm frames (38-44 ms measured), and every tick queued
behind it.  Now the detector hands over a job and goes on; the writer runs the jobs one at a
time, in the order they were queued.

Two kinds of job, because they differ in what may be given up when the disk is too slow:

* events (``put_event``) must never be lost.  When the queue is full the caller waits up to
  ``event_block_s`` for room; if there is still none the event is queued beyond the bound
  anyway (an event is a few hundred bytes and comes at a state change only), counted in
  ``events_over_bound`` and logged.  The detector is never held longer than that.
* frames (``put_frames``): black-box work.  When the queue is full the job is dropped, its
  frames counted in ``frames_dropped`` and logged (at most every 5 s).

``stop`` drains the queue and joins the thread.  A job queued after that, or while the
thread is dead, runs at once in the caller's thread, so nothing queued is lost.  With
``inline = True`` every job runs at once in the caller's thread: the old synchronous path,
kept for the benchmark's side-by-side comparison.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass

log = logging.getLogger(__name__)

Job = Callable[[], object]  # its result is not used (EventLog.retry's bool, for one)


@dataclass
class WriterCounts:
    jobs: int = 0  # jobs run (by the thread or inline)
    events_over_bound: int = 0  # events queued past a full queue after event_block_s
    frames_dropped: int = 0  # black-box frames given up because the queue was full
    job_errors: int = 0  # jobs that failed with an OSError (logged)
    max_depth: int = 0  # deepest the queue got

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class DiskWriter:
    def __init__(
        self, capacity: int = 1000, event_block_s: float = 0.1, inline: bool = False
    ) -> None:
        self.capacity = capacity
        self.event_block_s = event_block_s
        self.inline = inline
        self.counts = WriterCounts()
        self._jobs: deque[Job] = deque()
        self._cond = threading.Condition()
        self._busy = False  # the thread is running a job
        self._stopping = False
        self._exited = False  # the thread has returned (under the lock: no job is missed)
        self._last_drop_log = -float("inf")
        self._last_error_log = -float("inf")
        self._thread = threading.Thread(target=self._run, name="disk-writer", daemon=True)

    def start(self) -> None:
        self._thread.start()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _direct(self) -> bool:
        """Run jobs in the caller's thread: inline mode, or no writer thread to run them."""
        return self.inline or self._exited or not self._thread.is_alive()

    def put_event(self, job: Job) -> None:
        """Queue a job that must not be lost; waits at most ``event_block_s`` for room."""
        with self._cond:
            direct = self._direct()
            if not direct:
                if len(self._jobs) >= self.capacity:
                    self._cond.wait_for(lambda: len(self._jobs) < self.capacity, self.event_block_s)
                if len(self._jobs) >= self.capacity:
                    self.counts.events_over_bound += 1
                    log.error(
                        "disk writer: queue full (%d jobs) for %.2f s; event queued "
                        "beyond the bound (%d so far)",
                        len(self._jobs),
                        self.event_block_s,
                        self.counts.events_over_bound,
                    )
                self._append(job)
        if direct:
            self._call(job)

    def put_frames(self, job: Job, n_frames: int) -> bool:
        """Queue black-box work; False (frames counted as dropped) if the queue is full."""
        with self._cond:
            direct = self._direct()
            if not direct:
                if len(self._jobs) >= self.capacity:
                    self.counts.frames_dropped += n_frames
                    now = time.monotonic()
                    if now - self._last_drop_log > 5.0:
                        self._last_drop_log = now
                        log.error(
                            "disk writer: queue full (%d jobs); black-box frames "
                            "dropped: %d so far",
                            len(self._jobs),
                            self.counts.frames_dropped,
                        )
                    return False
                self._append(job)
        if direct:
            self._call(job)
        return True

    def count_dropped(self, n_frames: int) -> None:
        """Frames a job gave up (e.g. appends to a black box whose start was dropped)."""
        with self._cond:
            self.counts.frames_dropped += n_frames

    def _append(self, job: Job) -> None:
        self._jobs.append(job)
        self.counts.max_depth = max(self.counts.max_depth, len(self._jobs))
        self._cond.notify_all()

    def pending(self) -> int:
        """Jobs queued or running."""
        with self._cond:
            return len(self._jobs) + self._busy

    def wait_idle(self, timeout_s: float | None = None) -> bool:
        """Wait until every job queued so far has run; False on timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._jobs and not self._busy, timeout_s)

    def stop(self, timeout_s: float = 10.0) -> bool:
        """Run what is queued, then end the thread; False if it did not finish in time."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.error(
                "disk writer: %d job(s) not done after %.0f s (disk hung?)",
                self.pending(),
                timeout_s,
            )
            return False
        return True  # the thread drained the queue; later jobs run in the caller's thread

    def _call(self, job: Job) -> None:
        self.counts.jobs += 1
        try:
            job()
        except OSError as exc:  # a full or failing disk must not stop the other writes
            self.counts.job_errors += 1
            now = time.monotonic()
            if now - self._last_error_log > 5.0:  # a full disk fails every job: not every line
                self._last_error_log = now
                log.error("disk writer: %s (%d write errors)", exc, self.counts.job_errors)
        except Exception:  # nor may any other failure of one job end the thread
            self.counts.job_errors += 1
            log.exception("disk writer: a job failed (%d write errors)", self.counts.job_errors)

    def _run(self) -> None:
        cond = self._cond
        while True:
            with cond:
                self._busy = False
                cond.notify_all()  # wait_idle and put_event waiters
                cond.wait_for(lambda: self._jobs or self._stopping)
                if not self._jobs:
                    self._exited = True
                    return  # stopping and drained
                job = self._jobs.popleft()
                self._busy = True
                cond.notify_all()  # room for a blocked put_event
            self._call(job)
