"""What the daemon keeps on disk: the event log and the black box, written by one disk-writer
thread (``monitor.live.writer``) within one storage quota (``monitor.live.storage``).

The detector thread only queues work here: an event line (stamped with its ``seq`` and this
host's monotonic clock first), the black box's frames.  ``close`` is the disk's part of the
ordered shutdown: the black box's last frames and the event log's close are queued after
everything else, the writer drains its queue (every event written and fsynced) and stops.
"""

from __future__ import annotations

import logging
import time
from functools import partial
from typing import Any

from monitor.config.settings import MonitorConfig
from monitor.live.blackbox import BlackBox
from monitor.live.eventlog import EventLog
from monitor.live.storage import Quota
from monitor.live.writer import DiskWriter

log = logging.getLogger("monitor")

RETRY_S = 5.0  # how often events the disk refused are tried again


class DiskOutputs:
    """The event log, the black box, their writer thread (started here) and their quota."""

    def __init__(self, cfg: MonitorConfig) -> None:
        st = cfg.storage
        self.quota = Quota(st.quota_bytes, cfg.black_box.directory, cfg.event_log.path)
        self.event_log = EventLog(cfg.event_log.path, cfg.event_log.rotate_bytes, self.quota)
        self.writer = DiskWriter(st.writer_queue, st.event_block_s)
        self.black_box = BlackBox(cfg.black_box, cfg.bus.channel, self.writer, self.quota)
        self.writer.start()
        self.unwritten = 0  # events still not on disk when ``close`` returned
        self._errors_reported = 0  # disk_errors at the last ``trouble``
        self._last_retry_mono = 0.0

    @property
    def disk_errors(self) -> int:
        """Failed writes, rotations and deletions of the event log and black boxes."""
        return self.event_log.disk_errors + self.writer.counts.job_errors

    def log_event(self, ev: dict[str, Any]) -> None:
        """Queue an event-log line for the disk writer (which writes and fsyncs it)."""
        ev["mono"] = round(time.monotonic(), 6)  # this host's monotonic clock, s
        self.event_log.stamp(ev)
        self.writer.put_event(partial(self.event_log.write, ev))

    def trouble(self, now_mono: float) -> bool:
        """MON_Status's DiskError: events wait in memory for the disk, or a write failed
        since the last call.  Events waiting are queued for another try every ``RETRY_S``
        (the disk may be back)."""
        waiting = self.event_log.unwritten
        if waiting and now_mono - self._last_retry_mono >= RETRY_S:
            self._last_retry_mono = now_mono
            self.writer.put_event(self.event_log.retry)
        errors = self.disk_errors
        failed, self._errors_reported = errors != self._errors_reported, errors
        return bool(waiting) or failed

    def reconfigure(self, cfg: MonitorConfig, event_log: EventLog | None) -> None:
        """A reload: the black box's and the quota's settings, and a new event log (opened by
        ``monitor.live.reload.prepare`` when its path changed) once the old one's queued
        writes are done."""
        if event_log is not None:
            self.writer.put_event(self.event_log.close)  # after its queued writes
            self.quota.event_log_path = event_log.path
            self.event_log = event_log
        self.black_box.cfg = cfg.black_box
        self.quota.quota_bytes = cfg.storage.quota_bytes

    def close(self, timeout_s: float) -> None:
        """Write everything queued and close the files; ``unwritten`` counts the events
        still not on disk then (the disk refused them)."""
        self.black_box.close()  # queues the last post-alarm frames and the file's close
        self.writer.put_event(self.event_log.close)
        self.writer.stop(timeout_s)  # drained: every event written and fsynced, files closed
        if self.writer.counts.frames_dropped or self.writer.counts.events_over_bound:
            log.warning("disk writer: %s", self.writer.counts.as_dict())
        self.unwritten = self.event_log.unwritten + self.event_log.lost + self.writer.pending()
