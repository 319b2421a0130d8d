"""Loader for the ZeMA hydraulic test rig's cycle files (UCI "Condition monitoring of
hydraulic systems", Helwig, Pignanelli & Schuetze, I2MTC 2015, CC BY 4.0).

Folder layout (one folder = a set of work cycles):

- ``<SENSOR>.txt`` per sensor: tab-separated, one row per cycle, ``SAMPLES_PER_CYCLE`` (60)
  columns = seconds 0..59 of the 60 s load cycle at 1 Hz.  Units: PS1..PS6 bar, EPS1 W,
  FS1 FS2 L/min, TS1..TS4 degC, VS1 mm/s, CE %, CP kW, SE %.
- ``profile.txt``: one row per cycle, 5 tab-separated columns: cooler [%] (3, 20, 100),
  valve [%] (100, 90, 80, 73), pump leakage (0, 1, 2), accumulator [bar] (130, 115, 100,
  90), stable flag (0 stable, 1 static conditions not yet reached).
- ``cycles.txt`` (optional): the rig's original cycle number of each row; without it the
  row number (0-based) stands in.

Only the sensors asked for are read.  Every malformed file is an ``InputFileError`` naming
the file and line.  ``split`` and ``holdout`` decide which cycles train, set J0 and are
scored, so that no scored cycle was ever used for patterns or J0.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import InputFileError

SAMPLES_PER_CYCLE = 60  # 1 Hz over the rig's 60 s load cycle
SAMPLE_PERIOD_S = 1.0

#: Condition columns of profile.txt and the values the dataset documents for each.
CONDITIONS: dict[str, tuple[int, ...]] = {
    "cooler": (3, 20, 100),
    "valve": (100, 90, 80, 73),
    "pump_leak": (0, 1, 2),
    "accumulator": (130, 115, 100, 90),
    "stable": (0, 1),
}
#: Healthy (the issue's definition): valve 100 %, no pump leakage, accumulator 130 bar,
#: whatever the cooler state and the stable flag.
HEALTHY = {"valve": 100, "pump_leak": 0, "accumulator": 130}

J0_EVERY = 3  # every 3rd healthy --train cycle (per cooler state) is held out for J0

SENSOR_UNITS: dict[str, str] = {
    **{f"PS{i}": "bar" for i in range(1, 7)},
    "EPS1": "W",
    "FS1": "L/min",
    "FS2": "L/min",
    **{f"TS{i}": "degC" for i in range(1, 5)},
    "VS1": "mm/s",
    "CE": "%",
    "CP": "kW",
    "SE": "%",
}


@dataclass
class RigCycles:
    """Cycles of the rig: ``signals[name]`` is (cycles, 60) in the sensor's unit,
    ``profile[cond]`` (cycles,) int, ``cycle_id`` (cycles,) original cycle numbers."""

    folder: Path
    signals: dict[str, np.ndarray]
    profile: dict[str, np.ndarray]
    cycle_id: np.ndarray
    cycle_id_source: str  # "cycles.txt" or "row order"

    def __len__(self) -> int:
        return int(self.cycle_id.shape[0])

    @property
    def healthy(self) -> np.ndarray:
        """Boolean mask of healthy cycles (see ``HEALTHY``)."""
        mask = np.ones(len(self), dtype=bool)
        for cond, value in HEALTHY.items():
            mask &= self.profile[cond] == value
        return mask

    def subset(self, idx: np.ndarray) -> RigCycles:
        """The cycles at integer positions (or boolean mask) ``idx``, in that order."""
        return RigCycles(
            self.folder,
            {k: v[idx] for k, v in self.signals.items()},
            {k: v[idx] for k, v in self.profile.items()},
            self.cycle_id[idx],
            self.cycle_id_source,
        )

    def cycle_table(self, names: Sequence[str], i: int) -> np.ndarray:
        """Cycle ``i`` as a (60, len(names)) array, columns in the order of ``names``."""
        return np.column_stack([self.signals[n][i] for n in names])


def _read_matrix(path: Path, ncols: int | None) -> np.ndarray:
    """A tab-separated numeric matrix; every row must have ``ncols`` columns (or as many as
    the first row when None).  A trailing newline is fine; an empty line inside is not."""
    if not path.is_file():
        raise InputFileError(f"{path}: file not found (expected in the rig's folder layout)")
    try:
        text = path.read_text(encoding="ascii")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{path}: not a text file of numbers ({exc.reason})") from None
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read ({exc.strerror})") from None
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise InputFileError(f"{path}: empty file")
    rows = []
    for lineno, line in enumerate(lines, start=1):
        parts = line.strip().split("\t")
        if ncols is None:
            ncols = len(parts)
        if len(parts) != ncols:
            raise InputFileError(
                f"{path}:{lineno}: {len(parts)} tab-separated columns, expected {ncols}"
            )
        try:
            row = np.array(parts, dtype=np.float64)
        except ValueError:
            bad = next(j for j, p in enumerate(parts) if not _is_float(p))
            raise InputFileError(
                f"{path}:{lineno}: column {bad + 1}: {parts[bad]!r} is not a number"
            ) from None
        if not np.isfinite(row).all():
            bad = int(np.argwhere(~np.isfinite(row))[0][0])
            raise InputFileError(f"{path}:{lineno}: column {bad + 1}: value is not finite")
        rows.append(row)
    return np.vstack(rows)


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _check_rows(path: Path, n: int, expected: int, reference: Path) -> None:
    if n != expected:
        line = min(n, expected) + 1
        raise InputFileError(
            f"{path}:{line}: {n} cycles (rows) but {reference.name} has {expected}; "
            "every file of a folder needs one row per cycle"
        )


def load_rig(folder: Path | str, sensors: Iterable[str]) -> RigCycles:
    """Read ``profile.txt``, ``cycles.txt`` (if present) and ``<sensor>.txt`` for each
    sensor from ``folder``; validate shapes, numbers and condition values."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputFileError(f"{folder}: not a folder (expected the rig's cycle files)")
    prof_path = folder / "profile.txt"
    prof = _read_matrix(prof_path, len(CONDITIONS))
    n = prof.shape[0]
    profile: dict[str, np.ndarray] = {}
    for j, (cond, allowed) in enumerate(CONDITIONS.items()):
        col = prof[:, j]
        bad = ~np.isin(col, allowed)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputFileError(
                f"{prof_path}:{i + 1}: column {j + 1} ({cond}) is {col[i]:g}, expected one of "
                f"{', '.join(str(v) for v in allowed)}"
            )
        profile[cond] = col.astype(np.int64)

    cyc_path = folder / "cycles.txt"
    if cyc_path.exists():
        ids = _read_matrix(cyc_path, 1)[:, 0]
        _check_rows(cyc_path, ids.shape[0], n, prof_path)
        if np.any(ids != np.round(ids)) or np.any(ids < 0):
            i = int(np.argmax((ids != np.round(ids)) | (ids < 0)))
            raise InputFileError(f"{cyc_path}:{i + 1}: cycle number must be an integer >= 0")
        cycle_id = ids.astype(np.int64)
        if len(np.unique(cycle_id)) != n:
            raise InputFileError(f"{cyc_path}: a cycle number appears twice")
        source = "cycles.txt"
    else:
        cycle_id, source = np.arange(n, dtype=np.int64), "row order"

    signals: dict[str, np.ndarray] = {}
    for name in dict.fromkeys(sensors):
        path = folder / f"{name}.txt"
        m = _read_matrix(path, SAMPLES_PER_CYCLE)
        _check_rows(path, m.shape[0], n, prof_path)
        signals[name] = m
    return RigCycles(folder, signals, profile, cycle_id, source)


# --------------------------------------------------------------------------- split


def _even_spread(n: int, k: int | None) -> np.ndarray:
    """``k`` indices spread evenly over 0..n-1 (all when k is None or >= n)."""
    if k is None or k >= n:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, k).round().astype(np.int64))


def split(
    train: RigCycles, test: RigCycles, same_folder: bool, max_cycles: int | None
) -> tuple[RigCycles, RigCycles, dict[str, Any]]:
    """The --train and --test cycle sets, never sharing a cycle.

    Same folder: even original cycle numbers train, odd ones are scored.  Different
    folders: a cycle number present in both (when both come from cycles.txt) is dropped from
    the test set.  ``max_cycles`` keeps that many cycles of each side, evenly spread.
    """
    info: dict[str, Any] = {
        "same_folder": same_folder,
        "cycle_numbers_from": {"train": train.cycle_id_source, "test": test.cycle_id_source},
    }
    if same_folder:
        train = train.subset(np.flatnonzero(train.cycle_id % 2 == 0))
        test = test.subset(np.flatnonzero(test.cycle_id % 2 == 1))
        info["rule"] = "same folder: even original cycle numbers train, odd ones are scored"
    else:
        info["rule"] = "separate folders: all --train cycles train, all --test cycles are scored"
        if train.cycle_id_source == test.cycle_id_source == "cycles.txt":
            overlap = np.isin(test.cycle_id, train.cycle_id)
            info["test_cycles_dropped_as_also_in_train"] = int(overlap.sum())
            test = test.subset(np.flatnonzero(~overlap))
    if max_cycles is not None:
        train = train.subset(_even_spread(len(train), max_cycles))
        test = test.subset(_even_spread(len(test), max_cycles))
        info["max_cycles"] = max_cycles
    return train, test, info


def holdout(train: RigCycles) -> tuple[np.ndarray, np.ndarray]:
    """(pattern cycles, J0 cycles) among healthy --train cycles.

    Every ``J0_EVERY``-th healthy cycle of each cooler state goes to J0, so both sets see
    every cooler state (the cooler changes temperatures and viscosity a lot).
    """
    healthy = np.flatnonzero(train.healthy)
    pat, j0 = [], []
    for c in np.unique(train.profile["cooler"][healthy]):
        h = healthy[train.profile["cooler"][healthy] == c]
        take = np.zeros(len(h), dtype=bool)
        take[1::J0_EVERY] = True
        if len(h) >= 2 and not take.any():
            take[-1] = True
        pat.extend(h[~take])
        j0.extend(h[take])
    pat_a, j0_a = np.array(sorted(pat), dtype=np.int64), np.array(sorted(j0), dtype=np.int64)
    if len(pat_a) < 2 or len(j0_a) < 1:
        need = " and ".join(f"{k} {v}" for k, v in HEALTHY.items())
        raise InputFileError(
            f"{train.folder}: {len(healthy)} healthy cycles ({need}) to train on; need at "
            "least 3 (2 for the patterns, 1 for J0)"
        )
    return pat_a, j0_a
