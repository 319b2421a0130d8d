"""The daemon's event log: append-only JSON lines, flushed and fsynced per event, rotated by
size.

``monitor-events.jsonl`` is the current file.  When an event would take it past
``rotate_bytes`` it is renamed to ``.1`` (the older ones move up: ``.1`` to ``.2``, ...), so
the highest number is the oldest; only the storage quota (``monitor.live.storage``) deletes
rotated files, and never one that holds an unsent alarm.

Every event gets ``seq``, 1, 2, ... per event log, and a number is never issued twice: a
start continues from the largest of ``<event log>.seq`` (the last ``seq`` written), the
tails of the log and its rotated files, and ``<event log>.acked`` (the highest ``seq`` an
uploader took), so moving logs away, a damaged tail or a lost ``.seq`` never restarts the
numbering below what was acknowledged (``monitor.live.storage`` says how an uploader
acknowledges events).  Rotation moves only the names it makes (``.1``, ``.2``, ...; a
stray ``.01`` is left alone) and never renames onto an existing file.  Files are opened
without following symbolic links (``monitor.live.files``).
``stamp`` runs in the detector thread (so a hook sees the record as written); ``write`` and
``close`` in the disk writer's (``monitor.live.writer``).
"""

from __future__ import annotations

import datetime as dt
import errno
import json
import logging
import os
import time
from collections import deque
from contextlib import suppress
from pathlib import Path
from typing import Any

from monitor.bus.recovery import BusEvent
from monitor.detection.alarm import State
from monitor.errors import ConfigError
from monitor.live.files import NO_SPACE, append_all, fsync_dir, open_append, open_small
from monitor.live.storage import Quota, ack_path, acked_seq, rotated_logs

log = logging.getLogger(__name__)

_TAIL_BYTES = 64 * 1024  # enough for the last few events
_ERROR_LOG_S = 5.0  # at most one log line per this many seconds for repeated disk errors
MAX_PENDING = 100_000  # events held in memory while the disk refuses them (~30 MB)


class EventLog:
    """The event log at ``path``; ``rotate_bytes`` None: never rotated.

    A line the disk refuses (full, failing, read-only) is kept in memory, in ``seq`` order,
    and written before any later one: at the next event, at ``retry`` and at ``close``.
    On a full disk the quota first deletes black boxes and acknowledged logs
    (``Quota.make_room``), then the write is tried again.  ``unwritten`` says how many lines
    are still waiting; ``disk_errors`` counts every failed write, rotation or ``seq`` update.
    """

    def __init__(
        self, path: Path, rotate_bytes: int | None = None, quota: Quota | None = None
    ) -> None:
        self.path = Path(path)
        self.rotate_bytes = rotate_bytes
        self.quota = quota
        self.written = 0
        self.rotations = 0
        self.disk_errors = 0
        self.lost = 0  # lines given up beyond MAX_PENDING (logged)
        self._pending: deque[tuple[int | None, bytes]] = deque()
        self._last_error_log = -float("inf")
        self._fd: int | None = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            new = not os.path.lexists(self.path)
            self._fd = open_append(self.path)
            if new:  # the file's directory entry must survive a power cut too
                fsync_dir(self.path.parent)
            elif not _ends_with_newline(self.path):
                # A line torn by a power cut: end it, so the next event is a line of its own.
                append_all(self._fd, b"\n", os.fstat(self._fd).st_size)
                os.fsync(self._fd)
            self._seq_fd: int | None = open_small(seq_path(self.path))
            self.last_seq = self._start_seq()
        except OSError as exc:
            raise ConfigError(
                f"event_log.path: cannot open {exc.filename or self.path}: {exc.strerror}"
            ) from None
        self._size = os.fstat(self._fd).st_size

    def _start_seq(self) -> int:
        """The largest ``seq`` issued or acknowledged so far: numbering goes on above it."""
        assert self._seq_fd is not None
        tails = [_last_seq(p) or 0 for p in (self.path, *rotated_logs(self.path))]
        on_disk = max(max(tails), _read_seq(self._seq_fd))
        acked = acked_seq(self.path)
        if acked > on_disk:  # the logs and .seq were moved away or lost, .acked was not
            log.warning(
                "event log: %s acknowledges seq %d, above the %d found in the logs "
                "and %s; numbering goes on from %d",
                ack_path(self.path),
                acked,
                on_disk,
                seq_path(self.path),
                acked + 1,
            )
        return max(on_disk, acked)

    @property
    def unwritten(self) -> int:
        """Lines the disk has refused so far and that still wait in memory."""
        return len(self._pending)

    def stamp(self, record: dict[str, Any]) -> dict[str, Any]:
        """Give ``record`` the next ``seq`` (detector thread, before it is queued)."""
        self.last_seq += 1
        record["seq"] = self.last_seq
        return record

    def write(self, record: dict[str, Any]) -> None:
        """Append ``record`` as a line, after any line still waiting; never raises for a
        disk error (counted, logged, the line kept for the next try)."""
        if len(self._pending) >= MAX_PENDING:
            self._pending.popleft()
            self.lost += 1
            log.error(
                "event log: %d events waiting for the disk; the oldest given up (%d lost)",
                MAX_PENDING,
                self.lost,
            )
        seq = record.get("seq")
        self._pending.append((seq if isinstance(seq, int) else None, _line(record)))
        self.retry()

    def retry(self) -> bool:
        """Write the lines waiting, in order; True when none is left."""
        while self._pending:
            seq, line = self._pending[0]
            try:
                self._append(line)
            except OSError as exc:
                self._error(
                    f"cannot write event seq {seq} to {self.path}: {exc.strerror}; "
                    f"{len(self._pending)} event(s) kept in memory"
                )
                return False
            self._pending.popleft()
            self.written += 1
            if seq is not None:
                self._save_seq(seq)
        if self.quota is not None:
            self.quota.enforce()
        return True

    def _append(self, line: bytes) -> None:
        if self._fd is None:
            self._fd = open_append(self.path)
            self._size = os.fstat(self._fd).st_size
        limit = self.rotate_bytes
        if limit is not None and self._size and self._size + len(line) > limit:
            self._rotate(self._fd)
        try:
            append_all(self._fd, line, self._size)
        except OSError as exc:
            if exc.errno not in NO_SPACE or self.quota is None or not self.quota.make_room():
                raise
            log.warning(
                "event log: disk full; black boxes and acknowledged logs deleted to "
                "make room for an event"
            )
            append_all(self._fd, line, self._size)
        self._size += len(line)
        os.fsync(self._fd)

    def _save_seq(self, seq: int) -> None:
        # In place, fixed width: a rewrite of the same 21 bytes needs no new disk block, so
        # it works on a full disk, and a moved or damaged log cannot restart the numbering.
        try:
            if self._seq_fd is None:  # closed: reopened, as _append reopens the log
                self._seq_fd = open_small(seq_path(self.path))
            os.pwrite(self._seq_fd, b"%020d\n" % seq, 0)
            os.fsync(self._seq_fd)
        except OSError as exc:
            self._error(f"cannot update {seq_path(self.path)}: {exc.strerror}")

    def _rotate(self, fd: int) -> None:
        """Rename the full file away (``fd``: the open one) and start a new one; on failure
        write on in it."""
        try:
            os.fsync(fd)
            for p in rotated_logs(self.path):  # oldest first: each moves to a free name
                n = int(p.name.rsplit(".", 1)[1])
                _rename_new(p, p.with_name(f"{self.path.name}.{n + 1}"))
            _rename_new(self.path, self.path.with_name(self.path.name + ".1"))
        except OSError as exc:
            self._error(f"cannot rotate {self.path}: {exc.strerror}; writing on in it")
            return
        self._fd = None
        os.close(fd)
        self._size = 0
        self.rotations += 1
        self._fd = open_append(self.path)  # a failure here leaves it for the next write
        fsync_dir(self.path.parent)

    def _error(self, message: str) -> None:
        self.disk_errors += 1
        now = time.monotonic()
        if now - self._last_error_log >= _ERROR_LOG_S:
            self._last_error_log = now
            log.error("event log: %s (%d disk errors)", message, self.disk_errors)

    def close(self) -> None:
        """Write what waits (one more try), then close; ``unwritten`` tells what could not."""
        if self._pending:
            self.retry()
        if self._pending:
            log.error(
                "event log: %d event(s) could not be written to %s", len(self._pending), self.path
            )
        for fd in (self._fd, self._seq_fd):
            if fd is not None:
                with suppress(OSError):
                    os.close(fd)
        self._fd = self._seq_fd = None


def seq_path(path: Path) -> Path:
    """The small file holding the last ``seq`` written to event log ``path``."""
    return path.with_name(path.name + ".seq")


def _rename_new(src: Path, dst: Path) -> None:
    """Rename ``src`` to ``dst`` unless something is there already (a file planted or left
    at that name): a rotation must never replace a log that may hold an unsent alarm."""
    if os.path.lexists(dst):
        raise FileExistsError(errno.EEXIST, "a file of that name exists", str(dst))
    src.rename(dst)


def _line(record: dict[str, Any]) -> bytes:
    return (json.dumps(record) + "\n").encode("utf-8")


def _read_seq(fd: int) -> int:
    text = os.pread(fd, 64, 0).strip()
    return int(text) if text.isdigit() and len(text) <= 20 else 0


def _ends_with_newline(path: Path) -> bool:
    with path.open("rb") as fh:
        fh.seek(0, os.SEEK_END)
        if fh.tell() == 0:
            return True
        fh.seek(-1, os.SEEK_END)
        return fh.read(1) == b"\n"


def _last_seq(path: Path) -> int | None:
    """``seq`` of the last event in ``path`` that has one; None if none does."""
    try:
        with path.open("rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(0, fh.tell() - _TAIL_BYTES))
            lines = fh.read().splitlines()
    except FileNotFoundError:
        return None
    for line in reversed(lines):
        try:
            ev = json.loads(line)
        except ValueError:  # torn, or cut by the tail window
            continue
        if isinstance(ev, dict) and isinstance(ev.get("seq"), int):
            return ev["seq"]
    return None


def bus_event_record(
    ev: BusEvent, t_s: float | None, state: State, j: float, eps0: float, fault: str
) -> dict[str, Any]:
    """The event-log line of a bus event: the keys of a state change (the monitor's state
    and J at that moment, ``t`` the sample-clock time of the last row or null before the
    first, ``time`` the wall clock of the event) plus ``kind: "bus"`` and its details.
    Lines without ``kind`` are state changes, as before."""
    return {
        "t": None if t_s is None else round(t_s, 6),
        "time": dt.datetime.fromtimestamp(ev.wall_s, tz=dt.timezone.utc).isoformat(),
        "state": state.label,
        "J": float(j) if j == j else None,
        "threshold": eps0,
        "fault": fault if state is State.FAULT else None,
        "kind": "bus",
        "bus": ev.kind,
        "detail": ev.detail,
        "reopens": ev.reopens,
        "down_s": None if ev.down_s is None else round(ev.down_s, 3),
    }
