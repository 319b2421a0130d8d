"""One `monitor fleet run` per results folder at a time.

Two runs on one RESULTS would write the same parts and temporary files and merge each
other's tables half-written.  The lock is an advisory ``flock`` on RESULTS/.lock, held for
the whole run: the kernel drops it when the process ends however it ends (a SIGKILL or a
crash leaves no stale lock to clean up by hand).  It holds on a local filesystem; NFS
clients may not share ``flock`` locks.
"""

from __future__ import annotations

import fcntl
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from monitor.errors import MonitorError


class ResultsBusyError(MonitorError, OSError):
    """Another fleet run holds the results folder."""


@contextmanager
def results_lock(root: Path) -> Iterator[None]:
    """Hold RESULTS/.lock for the block, or raise :class:`ResultsBusyError` at once."""
    root.mkdir(parents=True, exist_ok=True)
    path = root / ".lock"
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip()
            raise ResultsBusyError(
                f"{root}: another `monitor fleet run` is writing these results"
                f"{f' ({holder})' if holder else ''}; wait for it to end, or give another --out"
            ) from None
        os.ftruncate(fd, 0)
        started = time.strftime("%Y-%m-%d %H:%M:%S %Z")
        os.pwrite(fd, f"pid {os.getpid()}, started {started}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # drops the lock
