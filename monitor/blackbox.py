"""Black box: the raw frames from ``pre_s`` before to ``post_s`` after each alarm, as candump.

Every frame taken off the bus (accepted or not: a bad frame may be the story) goes into a
bounded deque covering ``pre_s`` of bus time and at most ``max_frames`` frames.  When an
alarm is raised the deque is written to a new file, and frames keep being appended until
bus time passes the alarm by ``post_s`` (or the daemon stops).  At most ``max_files`` files
are kept; the oldest go first.
"""

from __future__ import annotations

import datetime as dt
import logging
from collections import deque
from pathlib import Path
from typing import TextIO

import can

from monitor.config import BlackBoxConfig
from monitor.errors import ConfigError
from monitor.io.candump import format_line

log = logging.getLogger(__name__)


class BlackBox:
    def __init__(self, cfg: BlackBoxConfig, channel: str = "can0") -> None:
        self.cfg = cfg
        self.channel = channel
        self.directory = Path(cfg.directory)
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(
                f"black_box.directory: cannot create {self.directory}: {exc.strerror}"
            ) from None
        self._recent: deque[can.Message] = deque(maxlen=cfg.max_frames)
        self._fh: TextIO | None = None
        self._until_s = 0.0
        self.files: list[Path] = []

    @property
    def recording(self) -> bool:
        return self._fh is not None

    def _line(self, msg: can.Message) -> str:
        return format_line(
            msg.timestamp, self.channel, msg.arbitration_id, msg.is_extended_id, bytes(msg.data)
        )

    def add(self, msg: can.Message) -> None:
        recent = self._recent
        recent.append(msg)
        # Trim by bus time; a clock that went backwards leaves older stamps in, bounded by
        # max_frames anyway.
        horizon = msg.timestamp - self.cfg.pre_s
        while recent and recent[0].timestamp < horizon:
            recent.popleft()
        if self._fh is not None:
            if msg.timestamp > self._until_s:
                self.close()
            else:
                self._fh.write(self._line(msg))

    def trigger(self, bus_time_s: float, label: str) -> Path | None:
        """Start a file at an alarm raised at ``bus_time_s``; None if it cannot be written."""
        self.close()
        stamp = dt.datetime.fromtimestamp(bus_time_s, tz=dt.timezone.utc)
        path = self.directory / f"alarm-{stamp:%Y%m%dT%H%M%S.%fZ}-{label}.log"
        try:
            fh = path.open("w", encoding="ascii", newline="\n")
            fh.writelines(self._line(m) for m in self._recent)
        except OSError as exc:
            log.error("black box: cannot write %s: %s", path, exc.strerror)
            return None
        self._fh = fh
        self._until_s = bus_time_s + self.cfg.post_s
        self.files.append(path)
        self._prune()
        return path

    def _prune(self) -> None:
        old = sorted(self.directory.glob("alarm-*.log"))
        for p in old[: max(0, len(old) - self.cfg.max_files)]:
            try:
                p.unlink()
            except OSError as exc:
                log.warning("black box: cannot delete %s: %s", p, exc.strerror)

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
