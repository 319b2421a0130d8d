"""Opening, writing and reading the daemon's own files safely.

The daemon often runs as root on a controller whose data directory others can write to
(an uploader, a service laptop).  Its files are therefore opened without following a
symbolic link (``O_NOFOLLOW``): a link planted at the event log's or a black box's name is
an error, never a way to overwrite its target.  Writes go out whole or not at all: a write
that fails half-way (a full disk) is cut back, so no torn line is left mid-file.
"""

from __future__ import annotations

import errno
import os
import stat
from contextlib import suppress
from pathlib import Path

#: Errors that mean "no room": deleting other files may help.
NO_SPACE = frozenset({errno.ENOSPC, errno.EDQUOT})

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)


def open_append(path: Path, exclusive: bool = False) -> int:
    """A descriptor appending to ``path`` (created 0644), never through a symbolic link.

    ``exclusive``: the file must not exist yet (``O_EXCL``)."""
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | _NOFOLLOW | _CLOEXEC
    if exclusive:
        flags |= os.O_EXCL
    fd = os.open(path, flags, 0o644)
    if not stat.S_ISREG(os.fstat(fd).st_mode):  # a FIFO or a device at our file's name
        os.close(fd)
        raise OSError(errno.EINVAL, "not a regular file", str(path))
    return fd


def open_small(path: Path) -> int:
    """A read-write descriptor on a small state file of the daemon's (created 0644), never
    through a symbolic link."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT | _NOFOLLOW | _CLOEXEC, 0o644)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(errno.EINVAL, "not a regular file", str(path))
    return fd


def append_all(fd: int, data: bytes, size_before: int) -> None:
    """Append ``data`` whole; on failure cut the file back to ``size_before`` and raise."""
    view = memoryview(data)
    try:
        while view:
            n = os.write(fd, view)
            view = view[n:]
    except OSError:
        # The caller keeps the data and retries; if even this fails a reader skips the line.
        with suppress(OSError):
            os.ftruncate(fd, size_before)
        raise


def fsync_dir(path: Path) -> None:
    """Make a new directory entry in ``path`` survive a power cut (where the OS allows)."""
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


def read_small(path: Path, limit: int = 64) -> bytes | None:
    """Up to ``limit`` bytes of a regular file, without blocking (a FIFO or device planted
    at the name is refused) and without following a link; None if it does not exist."""
    try:
        fd = os.open(path, os.O_RDONLY | _NONBLOCK | _NOFOLLOW | _CLOEXEC)
    except FileNotFoundError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        return os.read(fd, limit)
    finally:
        os.close(fd)
