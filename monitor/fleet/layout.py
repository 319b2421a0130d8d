"""The fleet input layout (docs/reference/contracts.md): what is there, in time order, with hashes.

FLEET/<machine_id>/commissioning/*.log|*.csv   normal operation (optional)
FLEET/<machine_id>/logs/*.log|*.csv           operating logs; file-name order is time order

Only regular files and folders inside FLEET are read: a symbolic link (to a file or a
folder, inside the fleet or out of it), a FIFO, a device or a socket is refused, each with
its reason (a FIFO or /dev/zero would hang the run; a link reads what the fleet does not
hold).  Entries are told apart by ``lstat``, which never follows a link.
"""

from __future__ import annotations

import stat
from dataclasses import dataclass, field
from pathlib import Path

from monitor.errors import InputFileError

SUFFIXES = (".log", ".csv")


@dataclass(frozen=True)
class Machine:
    machine_id: str
    commissioning: tuple[Path, ...]
    logs: tuple[Path, ...]


@dataclass(frozen=True)
class Refused:
    """An entry of the fleet that is not read: its name relative to FLEET (a folder's ends
    with '/'), its machine, and why."""

    machine: str
    name: str
    reason: str


@dataclass(frozen=True)
class Fleet:
    root: Path
    machines: tuple[Machine, ...] = field(default_factory=tuple)
    refused: tuple[Refused, ...] = field(default_factory=tuple)

    def relative(self, path: Path) -> str:
        """A log's name in the results: its path relative to FLEET, with '/'."""
        return path.relative_to(self.root).as_posix()


def not_regular(mode: int) -> str | None:
    """Why an entry of this ``lstat`` mode is not read, or None for a file or folder."""
    if stat.S_ISLNK(mode):
        return "a symbolic link, not followed (only files inside the fleet folder are read)"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe), not a file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device, not a file"
    if stat.S_ISSOCK(mode):
        return "a socket, not a file"
    return None


def _folder(path: Path, machine: str, root: Path, refused: list[Refused]) -> bool:
    """Whether ``path`` is a folder to read (a refused one is added to ``refused``)."""
    try:
        mode = path.lstat().st_mode
    except FileNotFoundError:
        return False
    why = not_regular(mode) or (None if stat.S_ISDIR(mode) else "a file, not a folder")
    if why:
        refused.append(Refused(machine, path.relative_to(root).as_posix() + "/", why))
    return why is None


def _recordings(folder: Path, machine: str, root: Path, refused: list[Refused]) -> tuple:
    if not _folder(folder, machine, root, refused):
        return ()
    out = []
    for p in sorted(folder.iterdir()):
        if p.suffix.lower() not in SUFFIXES:
            continue
        mode = p.lstat().st_mode
        why = not_regular(mode) or (None if stat.S_ISREG(mode) else "a folder, not a file")
        if why:
            refused.append(Refused(machine, p.relative_to(root).as_posix(), why))
        else:
            out.append(p)
    return tuple(out)


def scan_fleet(root: Path) -> Fleet:
    """Machines (sub-folders of ``root``) with their commissioning and operating logs, and
    what is refused."""
    if not root.is_dir():
        raise InputFileError(f"{root}: no such fleet folder")
    machines, refused = [], []
    for d in sorted(root.iterdir()):
        if d.name.startswith("."):
            continue
        mode = d.lstat().st_mode
        if stat.S_ISLNK(mode) or not stat.S_ISDIR(mode):
            if stat.S_ISLNK(mode) and d.is_dir():  # a linked machine folder: say so
                refused.append(Refused(d.name, f"{d.name}/", not_regular(mode) or ""))
            continue  # files beside the machines (answer_key.json, ...) are not machines
        commissioning = _recordings(d / "commissioning", d.name, root, refused)
        machines.append(
            Machine(d.name, commissioning, _recordings(d / "logs", d.name, root, refused))
        )
    if not machines and not refused:
        raise InputFileError(f"{root}: no machine folders (expected FLEET/<machine_id>/logs/)")
    return Fleet(root, tuple(machines), tuple(refused))
