"""Black box: the raw frames from ``pre_s`` before to ``post_s`` after each alarm, as candump.

Every frame taken off the bus (accepted or not: a bad frame may be the story) goes into a
bounded deque covering ``pre_s`` of bus time and at most ``max_frames`` frames.  When an
alarm is raised the deque is written to a new file, and frames keep being appended until
bus time passes the alarm by ``post_s`` (or the daemon stops).  At most ``max_files`` files
are kept, and the storage quota (``monitor.live.storage``) deletes the oldest first; oldest
by the ``seq`` of the alarm's event (``-seq<N>`` in the name), not by the time in the name,
which a clock that ran ahead would make lie.

The detector thread only keeps the deque and hands over work: at an alarm a snapshot of the
deque (references to the frames, no copies), after it the frames in batches of
``BATCH_FRAMES``.  Formatting, writing, fsync and deleting run in the disk writer
(``monitor.live.writer``), which may drop black-box work when its queue is full (counted).
"""

from __future__ import annotations

import datetime as dt
import errno
import logging
import os
import time
from collections import deque
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import TextIO

import can

from monitor.config.settings import BlackBoxConfig
from monitor.errors import ConfigError
from monitor.io.candump import format_line
from monitor.live.files import open_append
from monitor.live.storage import Quota, black_boxes
from monitor.live.writer import DiskWriter

log = logging.getLogger(__name__)

BATCH_FRAMES = 256  # post-alarm frames per writer job (under 1 s of a 300 frames/s bus)
_CHUNK_LINES = 256  # lines formatted (about 0.7 ms of CPU) between two pauses
# Formatting is Python holding the GIL: without a pause between chunks the detector thread
# waits up to a switch interval (5 ms) for it at every tick of a long dump.
_PAUSE_S = 0.0005


class BlackBox:
    def __init__(
        self,
        cfg: BlackBoxConfig,
        channel: str = "can0",
        writer: DiskWriter | None = None,
        quota: Quota | None = None,
    ) -> None:
        """``writer`` None: every write happens at once in the caller's thread."""
        self.cfg = cfg
        self.channel = channel
        self.directory = Path(cfg.directory)
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(
                f"black_box.directory: cannot create {self.directory}: {exc.strerror}"
            ) from None
        self.writer = writer if writer is not None else DiskWriter(inline=True)
        self.quota = quota
        self._recent: deque[can.Message] = deque(maxlen=cfg.max_frames)
        self._path: Path | None = None  # the file being recorded (detector's view)
        self._batch: list[can.Message] = []
        self._until_s = 0.0
        self.files: list[Path] = []
        self._names: set[Path] = set()
        # Writer-thread side: the open file and what it is.
        self._fh: TextIO | None = None
        self._fh_path: Path | None = None

    @property
    def recording(self) -> bool:
        return self._path is not None

    def add(self, msg: can.Message) -> None:
        recent = self._recent
        recent.append(msg)
        # Trim by bus time; a clock that went backwards leaves older stamps in, bounded by
        # max_frames anyway.
        horizon = msg.timestamp - self.cfg.pre_s
        while recent and recent[0].timestamp < horizon:
            recent.popleft()
        if self._path is not None:
            if msg.timestamp > self._until_s:
                self.close()
            else:
                self._batch.append(msg)
                if len(self._batch) >= BATCH_FRAMES:
                    self._hand_over(self._path)

    def trigger(self, bus_time_s: float, label: str, seq: int | None = None) -> Path:
        """Start a file at an alarm raised at ``bus_time_s`` (``seq``: its event's, which
        orders the boxes for retention); returns its path (the disk writer writes it; a
        failure there is logged)."""
        self.close()
        stamp = dt.datetime.fromtimestamp(bus_time_s, tz=dt.timezone.utc)
        tail = "" if seq is None else f"-seq{seq}"
        path = self.directory / f"alarm-{stamp:%Y%m%dT%H%M%S.%fZ}-{label}{tail}.log"
        if path in self._names:  # two alarms at one instant (several loops, a clock reset)
            path = path.with_name(f"{path.stem}-{len(self.files) + 1}.log")
        self._names.add(path)
        frames = tuple(self._recent)
        self.writer.put_frames(partial(self._start, path, frames), len(frames))
        self._path = path
        self._until_s = bus_time_s + self.cfg.post_s
        self.files.append(path)
        return path

    def _hand_over(self, path: Path) -> None:
        frames, self._batch = self._batch, []
        self.writer.put_frames(partial(self._append, path, frames), len(frames))

    def close(self) -> None:
        """End the recording (if any): the last frames and the close go to the writer."""
        if self._path is None:
            return
        if self._batch:
            self._hand_over(self._path)
        # Closing must not be dropped: a later file would find this one still open.
        self.writer.put_event(partial(self._finish, self._path))
        self._path = None

    # -- disk-writer thread ----------------------------------------------------------------

    def _lines(self, fh: TextIO, frames: Sequence[can.Message]) -> None:
        ch = self.channel
        pause = 0.0 if self.writer.inline else _PAUSE_S  # inline: the old path, unchanged
        for i in range(0, len(frames), _CHUNK_LINES):
            if i:
                time.sleep(pause)
            fh.write(
                "".join(
                    format_line(m.timestamp, ch, m.arbitration_id, m.is_extended_id, bytes(m.data))
                    for m in frames[i : i + _CHUNK_LINES]
                )
            )

    def _start(self, path: Path, frames: Sequence[can.Message]) -> None:
        self._finish(self._fh_path)
        try:
            fh, name = _create(path)
        except OSError as exc:
            log.error("black box: cannot write %s: %s", path, exc.strerror)
            return
        self._fh, self._fh_path = fh, path
        if self.quota is not None:
            self.quota.recording = name  # never deleted while written, even on a full disk
        self._lines(fh, frames)
        log.info("black box: %s (%d frames before the alarm)", name, len(frames))
        self._prune(name)
        if self.quota is not None:
            self.quota.enforce()

    def _append(self, path: Path, frames: Sequence[can.Message]) -> None:
        if self._fh is not None and path == self._fh_path:
            self._lines(self._fh, frames)
        else:  # its start was dropped (writer queue full) or could not be written
            self.writer.count_dropped(len(frames))

    def _finish(self, path: Path | None) -> None:
        if self._fh is None or path != self._fh_path:
            return
        fh, self._fh, self._fh_path = self._fh, None, None
        if self.quota is not None:
            self.quota.recording = None
        fh.flush()
        os.fsync(fh.fileno())
        fh.close()
        if self.quota is not None:
            self.quota.enforce()

    def _prune(self, recording: Path) -> None:
        """Keep the ``max_files`` newest boxes by ``seq`` (the one being written always)."""
        old = [p for p in black_boxes(self.directory) if p != recording]
        for p in old[: max(0, len(old) + 1 - self.cfg.max_files)]:
            try:
                p.unlink()
            except OSError as exc:
                log.warning("black box: cannot delete %s: %s", p, exc.strerror)


def _create(path: Path) -> tuple[TextIO, Path]:
    """A new black-box file at ``path``, or beside it if that name is taken (a file left by
    an earlier run, or something planted there): never through a link, never over a file."""
    for n in range(100):
        name = path if n == 0 else path.with_name(f"{path.stem}~{n}.log")
        try:
            fd = open_append(name, exclusive=True)
        except FileExistsError:
            continue
        return os.fdopen(fd, "w", encoding="ascii", newline="\n"), name
    raise FileExistsError(errno.EEXIST, "100 files of that name exist", str(path))
