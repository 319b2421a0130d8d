"""The daemon's event log: append-only JSON lines, flushed and fsynced per event, rotated by
size.

``monitor-events.jsonl`` is the current file.  When an event would take it past
``rotate_bytes`` it is renamed to ``.1`` (the older ones move up: ``.1`` to ``.2``, ...), so
the highest number is the oldest; only the storage quota (``monitor.live.storage``) deletes
rotated files, and never one that holds an unsent alarm.

Every event gets ``seq``, 1, 2, ... per event log: a restart appends and continues from the
last ``seq`` on disk, which is how an uploader acknowledges events (``monitor.live.storage``).
``stamp`` runs in the detector thread (so a hook sees the record as written); ``write`` and
``close`` in the disk writer's (``monitor.live.writer``).
"""

from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path
from typing import Any

from monitor.bus.recovery import BusEvent
from monitor.detection.alarm import State
from monitor.errors import ConfigError
from monitor.live.storage import Quota, rotated_logs

_TAIL_BYTES = 64 * 1024  # enough for the last few events


class EventLog:
    def __init__(
        self, path: Path, rotate_bytes: int | None = None, quota: Quota | None = None
    ) -> None:
        self.path = Path(path)
        self.rotate_bytes = rotate_bytes
        self.quota = quota
        self.written = 0
        self.rotations = 0
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            new = not self.path.exists()
            self._fh = self.path.open("a", encoding="utf-8")
            if new:  # the file's directory entry must survive a power cut too
                _fsync_dir(self.path.parent)
            elif not _ends_with_newline(self.path):
                # A line torn by a power cut: end it, so the next event is a line of its own.
                self._fh.write("\n")
                self._sync()
            self.last_seq = self._last_seq_on_disk()
        except OSError as exc:
            raise ConfigError(f"event_log.path: cannot open {self.path}: {exc.strerror}") from None
        self._size = self.path.stat().st_size

    def _last_seq_on_disk(self) -> int:
        for p in (self.path, *reversed(rotated_logs(self.path))):  # newest file first
            seq = _last_seq(p)
            if seq is not None:
                return seq
        return 0

    def stamp(self, record: dict[str, Any]) -> dict[str, Any]:
        """Give ``record`` the next ``seq`` (detector thread, before it is queued)."""
        self.last_seq += 1
        record["seq"] = self.last_seq
        return record

    def write(self, record: dict[str, Any]) -> None:
        line = json.dumps(record) + "\n"
        n = len(line.encode("utf-8"))
        if self.rotate_bytes is not None and self._size and self._size + n > self.rotate_bytes:
            self._rotate()
        self._fh.write(line)
        self._sync()
        self._size += n
        self.written += 1
        if self.quota is not None:
            self.quota.enforce()

    def _sync(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def _rotate(self) -> None:
        self._sync()
        self._fh.close()
        for p in rotated_logs(self.path):  # oldest first, so no rename overwrites a file
            n = int(p.name.rsplit(".", 1)[1])
            p.rename(p.with_name(f"{self.path.name}.{n + 1}"))
        self.path.rename(self.path.with_name(self.path.name + ".1"))
        self._fh = self.path.open("a", encoding="utf-8")
        _fsync_dir(self.path.parent)
        self._size = 0
        self.rotations += 1

    def close(self) -> None:
        if not self._fh.closed:
            self._sync()
            self._fh.close()


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


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # not every filesystem lets a directory be fsynced
    finally:
        os.close(fd)


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
