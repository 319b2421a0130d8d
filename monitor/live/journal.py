"""Logging for journald: the priority prefix on each line, no timestamps of our own."""

from __future__ import annotations

import logging
import sys
from typing import TextIO


class JournalFormatter(logging.Formatter):
    """``<priority>message``: journald reads the syslog priority prefix from stderr and adds
    its own timestamps, so none here."""

    _PRIORITY = {
        logging.DEBUG: 7,
        logging.INFO: 6,
        logging.WARNING: 4,
        logging.ERROR: 3,
        logging.CRITICAL: 2,
    }

    def format(self, record: logging.LogRecord) -> str:
        prio = self._PRIORITY.get(record.levelno, 6)
        text = super().format(record)
        return "\n".join(f"<{prio}>{line}" for line in text.splitlines())


class _Stderr(logging.StreamHandler):
    """A handler on whatever ``sys.stderr`` is when a record comes: a process that swaps its
    stderr (the test suite's captures, one after the other) never writes to a closed one."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, _value: TextIO) -> None:
        pass


def setup_logging(level: int = logging.INFO) -> None:
    handler = _Stderr()
    handler.setFormatter(JournalFormatter("%(name)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
