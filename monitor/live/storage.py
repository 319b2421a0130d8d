"""Disk quota for the daemon's files: the black boxes and the event log, together.

What counts: every ``alarm-*.log`` in the black-box directory, the event log
(``monitor-events.jsonl``) and its rotated files (``monitor-events.jsonl.1``, ``.2``, ...,
the highest number the oldest).  When they take more than the quota, files are deleted in
this order until they fit:

1. black boxes, oldest first by the ``seq`` of their alarm's event (in the name,
   ``-seq<N>``; a name without one counts as older than any with one, then by name), never
   the one being recorded nor the newest alarm's: a clock that ran ahead cannot make a new
   box look old;
2. rotated event-log files, oldest first, stopping at the first one that holds an *unsent
   alarm*.  The current event log is never deleted.

On a full disk (``make_room``) only files on the event log's filesystem are deleted: a black
box elsewhere frees nothing where the event waits.

An alarm is an event of the detector (not a ``kind: "bus"`` line) whose state is neither
``normal`` nor ``inactive`` (a fault or a sensor fault).  Every event carries ``seq`` (1,
2, ... per event log, continued across restarts).
*Unsent* means not yet acknowledged by whatever takes the events off the machine (a
telematics uploader, a service tool): it acknowledges by writing the highest ``seq`` it has
stored safely, as a decimal integer, to ``<event log>.acked`` (write a temporary file and
rename it).  Without that file nothing is acknowledged, so no rotated file with an alarm is
ever deleted.  If the files still do not fit, the quota is exceeded rather than an alarm
lost: counted in ``over_quota`` and logged.  The quota is checked after every event, and
when a black box starts and ends, so it can be overshot by one black box's post-alarm frames.

Lines without ``seq`` (event logs written before it existed) count as acknowledged.
Runs in the disk-writer thread (``monitor.live.writer``).
"""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path

from monitor.live.files import read_small

log = logging.getLogger(__name__)

NOT_ALARMS = frozenset({"normal", "inactive"})


def rotated_logs(path: Path) -> list[Path]:
    """Rotated files of event log ``path``, oldest (highest number) first: only the names a
    rotation makes (``.1``, ``.2``, ...; not ``.01`` or ``.1.gz``, which are left alone)."""
    pattern = re.compile(re.escape(path.name) + r"\.([1-9]\d{0,8})")
    found = []
    for p in path.parent.glob(path.name + ".*"):
        m = pattern.fullmatch(p.name)
        if m:
            found.append((int(m.group(1)), p))
    return [p for _, p in sorted(found, reverse=True)]


_BOX_SEQ = re.compile(r"-seq(\d{1,18})(?:-\d+)?(?:~\d+)?\.log")


def box_seq(path: Path) -> int:
    """The ``seq`` of the alarm event a black box belongs to (0: its name has none)."""
    m = _BOX_SEQ.search(path.name)
    return int(m.group(1)) if m else 0


def black_boxes(directory: Path) -> list[Path]:
    """Black-box files in ``directory``, oldest first by their alarm's ``seq``."""
    return sorted(directory.glob("alarm-*.log"), key=lambda p: (box_seq(p), p.name))


def ack_path(path: Path) -> Path:
    return path.with_name(path.name + ".acked")


def acked_seq(path: Path) -> int:
    """The highest ``seq`` acknowledged for event log ``path`` (0: none).  Read without
    blocking and without following a link: a FIFO or a device planted there acknowledges
    nothing."""
    try:
        raw = read_small(ack_path(path))
    except OSError as exc:
        log.warning(
            "cannot read %s (%s): treating every event as unsent", ack_path(path), exc.strerror
        )
        return 0
    if raw is None:
        return 0
    text = raw.decode("ascii", "replace").strip()
    try:
        if not text.isdigit():
            raise ValueError(text)
        return int(text)
    except ValueError:
        log.warning(
            "%s holds %r, not a whole number: treating every event as unsent",
            ack_path(path),
            text[:40],
        )
        return 0


def last_alarm_seq(path: Path) -> int:
    """The highest ``seq`` of an alarm in event-log file ``path`` (0: none)."""
    best = 0
    with path.open("rb") as fh:
        for line in fh:
            try:
                ev = json.loads(line)
            except ValueError:  # a line torn by a power cut
                continue
            if isinstance(ev, dict) and "kind" not in ev and ev.get("state") not in NOT_ALARMS:
                seq = ev.get("seq")
                if isinstance(seq, int):
                    best = max(best, seq)
    return best


class Quota:
    """Keeps ``black_box_dir``'s black boxes and the event log at ``event_log_path`` (with
    its rotated files) within ``quota_bytes`` together."""

    def __init__(self, quota_bytes: int, black_box_dir: Path, event_log_path: Path) -> None:
        self.quota_bytes = quota_bytes
        self.black_box_dir = Path(black_box_dir)
        self.event_log_path = Path(event_log_path)
        self.deleted_black_boxes = 0
        self.deleted_event_logs = 0
        self.over_quota = 0  # checks that ended over the quota (unsent alarms kept)
        self._over = False
        self.recording: Path | None = None  # the black box being written (set by it)
        # (inode, size, mtime) of a rotated file -> its last alarm seq: rotated files do
        # not change, and the check runs after every event.
        self._alarm_seq: dict[tuple[int, int, int], int] = {}

    def black_boxes(self) -> list[Path]:
        """Black-box files, oldest first (by their alarm's ``seq``)."""
        return black_boxes(self.black_box_dir)

    def _unsent_alarm(self, path: Path, acked: int) -> bool:
        st = path.stat()
        key = (st.st_ino, st.st_size, st.st_mtime_ns)
        if key not in self._alarm_seq:
            self._alarm_seq[key] = last_alarm_seq(path)
        return self._alarm_seq[key] > acked

    def make_room(self) -> bool:
        """A full disk and an event to write: delete every file the rules allow (black boxes
        first, then acknowledged rotated logs) on the event log's filesystem; True if
        anything was deleted."""
        before = self.deleted_black_boxes + self.deleted_event_logs
        try:
            device = self.event_log_path.parent.stat().st_dev
        except OSError:
            return False
        self.enforce(limit_bytes=0, device=device)
        return self.deleted_black_boxes + self.deleted_event_logs > before

    def enforce(
        self,
        recording: Path | None = None,
        limit_bytes: int | None = None,
        device: int | None = None,
    ) -> int:
        """Delete files as the module says until they fit; return the bytes in use.

        ``recording``: a black box being written, never deleted (nor ``self.recording``,
        nor the newest box).  ``limit_bytes``: the target instead of the quota
        (``make_room``); ``device``: delete only files on that filesystem (``st_dev``).
        """
        limit = self.quota_bytes if limit_bytes is None else limit_bytes
        boxes = [(p, _size(p)) for p in self.black_boxes()]
        rotated = [(p, _size(p)) for p in rotated_logs(self.event_log_path)]
        used = sum(s for _, s in boxes) + sum(s for _, s in rotated)
        used += _size(self.event_log_path)
        keep = {recording, self.recording, boxes[-1][0] if boxes else None}
        for p, size in boxes:
            if used <= limit:
                break
            if p in keep or not _on(p, device):
                continue
            if _unlink(p):
                used -= size
                self.deleted_black_boxes += 1
                log.info("storage quota: deleted black box %s (%d bytes)", p.name, size)
        acked = None
        for p, size in rotated:
            if used <= limit:
                break
            acked = acked_seq(self.event_log_path) if acked is None else acked
            if self._unsent_alarm(p, acked):
                break
            if not _on(p, device):
                continue
            if _unlink(p):
                used -= size
                self.deleted_event_logs += 1
                log.info("storage quota: deleted event log %s (%d bytes)", p.name, size)
        if limit_bytes is not None:
            return used
        over = used > self.quota_bytes
        if over:
            self.over_quota += 1
            if not self._over:  # once per excursion, not at every event
                log.warning(
                    "storage quota exceeded: %d of %d bytes; the rest holds unsent "
                    "alarms (acknowledged up to seq %s in %s) or the current files",
                    used,
                    self.quota_bytes,
                    acked_seq(self.event_log_path),
                    ack_path(self.event_log_path),
                )
        self._over = over
        return used


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return 0


def _on(path: Path, device: int | None) -> bool:
    """Whether ``path`` lies on filesystem ``device`` (None: any)."""
    if device is None:
        return True
    try:
        return path.lstat().st_dev == device
    except OSError:
        return False


def _unlink(path: Path) -> bool:
    try:
        path.unlink()
    except FileNotFoundError:
        return False
    except OSError as exc:
        log.warning("storage quota: cannot delete %s: %s", path, exc.strerror)
        return False
    return True
