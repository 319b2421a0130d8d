"""A recording: physical signals on a time axis, whatever file or bus they came from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monitor.errors import InputFileError
from monitor.signals import DERIVED, ROD_SPEED_SPAN, SIGNAL_NAMES, rod_speed_mm_s


@dataclass
class Recording:
    """Rows of physical signals at (nominally) 100 Hz.

    ``t`` is in seconds and increasing; ``columns`` maps a signal name (contract names,
    units as in ``monitor.signals.UNITS``) to a float64 array of the same length as ``t``.
    NaN marks a missing sample (an empty CSV field or a stale frame), never a file error.
    ``source`` names where the data came from, for messages.
    """

    t: np.ndarray
    columns: dict[str, np.ndarray]
    source: str = "<memory>"
    meta: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=np.float64)
        n = self.t.shape[0]
        for name, values in list(self.columns.items()):
            arr = np.asarray(values, dtype=np.float64)
            if arr.shape != (n,):
                raise InputFileError(
                    f"{self.source}: column {name!r} has {arr.shape[0]} samples, t has {n}"
                )
            self.columns[name] = arr

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "t":
            return self.t
        try:
            return self.columns[name]
        except KeyError:
            if name in DERIVED and DERIVED[name] in self.columns:
                return self._derived(name)
            raise InputFileError(f"{self.source}: no signal {name!r}") from None

    def has(self, name: str) -> bool:
        return name == "t" or name in self.columns or DERIVED.get(name, "") in self.columns

    def _derived(self, name: str) -> np.ndarray:
        """A derived signal (``monitor.signals.DERIVED``; only RodSpeed today), computed on
        each read, never stored: RodPos ``ROD_SPEED_SPAN`` rows apart (the first rows back
        to the first row), as the live ticker computes it row by row."""
        pos = self.columns[DERIVED[name]]
        k = min(ROD_SPEED_SPAN, pos.shape[0])
        first = pos[0] if pos.shape[0] else np.nan
        then = np.concatenate((np.full(k, first), pos[: pos.shape[0] - k]))
        return np.asarray(rod_speed_mm_s(pos, then), dtype=np.float64)

    def require(self, names: tuple[str, ...] = SIGNAL_NAMES) -> None:
        """Raise naming the file and every missing contract signal."""
        missing = [n for n in names if n not in self.columns]
        if missing:
            raise InputFileError(f"{self.source}: missing required signal(s) {', '.join(missing)}")
