"""The fleet input layout (docs/reference/contracts.md): what is there, in time order, with hashes.

FLEET/<machine_id>/commissioning/*.log|*.csv   normal operation (optional)
FLEET/<machine_id>/logs/*.log|*.csv           operating logs; file-name order is time order
"""

from __future__ import annotations

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
class Fleet:
    root: Path
    machines: tuple[Machine, ...] = field(default_factory=tuple)

    def relative(self, path: Path) -> str:
        """A log's name in the results: its path relative to FLEET, with '/'."""
        return path.relative_to(self.root).as_posix()


def _recordings(folder: Path) -> tuple[Path, ...]:
    if not folder.is_dir():
        return ()
    return tuple(sorted(p for p in folder.iterdir() if p.suffix.lower() in SUFFIXES))


def scan_fleet(root: Path) -> Fleet:
    """Machines (sub-folders of ``root``) with their commissioning and operating logs."""
    if not root.is_dir():
        raise InputFileError(f"{root}: no such fleet folder")
    machines = tuple(
        Machine(d.name, _recordings(d / "commissioning"), _recordings(d / "logs"))
        for d in sorted(root.iterdir())
        if d.is_dir() and not d.name.startswith(".")
    )
    if not machines:
        raise InputFileError(f"{root}: no machine folders (expected FLEET/<machine_id>/logs/)")
    return Fleet(root, machines)
