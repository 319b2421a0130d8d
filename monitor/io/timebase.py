"""A recording's time column, taken from the data: checked, and put on the 100 Hz grid.

The contract: ``t`` in seconds, rows nominally 10 ms apart, a few ms of jitter normal, a gap
of more than 3 periods missing data (not an error).  A time column the tools cannot trust is
refused with its first bad line: non-finite or absurd values (beyond ``MAX_ABS_T_S``), time
that does not increase, one step longer than ``MAX_STEP_S`` (a unit error, or two recordings
in one file), a recording longer than ``MAX_SPAN_S``.  Rows at another rate are resampled to
100 Hz when the rate lies within ``MIN_RATE_HZ``..``MAX_RATE_HZ`` (pressures and flows
linearly, commands held, gaps kept as gaps), refused with the measured rate otherwise: below
50 Hz the 100 Hz model's dynamics cannot be rebuilt from the rows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from monitor.errors import InputFileError
from monitor.signals import COMMAND_NAMES, SAMPLE_PERIOD_S, SAMPLE_RATE_HZ

#: Slowest rows that are resampled (Hz): below, the loop's dynamics are lost between rows.
MIN_RATE_HZ = 50.0
#: Fastest rows that are resampled (Hz): above, ``t`` is most likely not in seconds.
MAX_RATE_HZ = 10_000.0
#: A median row step within this share of 10 ms is the contract's 100 Hz (rows kept as read).
NOMINAL_TOLERANCE = 0.01
#: Longest step between two rows (s): a longer pause is a unit error or two recordings.
MAX_STEP_S = 600.0
#: Longest recording (s): a year.
MAX_SPAN_S = 366 * 86400.0
#: Largest |t| (s), some 300 years: beyond, float64 cannot hold 10 ms steps for long.
MAX_ABS_T_S = 1e10
#: A step longer than this many median steps is a gap (missing data), not resampled across.
GAP_PERIODS = 3.0


@dataclass(frozen=True)
class TimeBase:
    """What ``check_time`` measured: the median row step (s) and whether to resample."""

    step_s: float
    resample: bool

    @property
    def rate_hz(self) -> float:
        return 1.0 / self.step_s


def _at(source: str, lines: Sequence[int] | np.ndarray | None, i: int) -> str:
    return f"{source}:{lines[i]}" if lines is not None else f"{source}: row {i + 1}"


def check_time(
    t: np.ndarray, source: str, lines: Sequence[int] | np.ndarray | None = None
) -> TimeBase:
    """Refuse a time column the tools cannot trust (``InputFileError`` naming the first bad
    line: ``lines[i]`` is the file line of row i) and say whether its rows need resampling."""
    bad = np.flatnonzero(~np.isfinite(t) | (np.abs(t) > MAX_ABS_T_S))
    if bad.size:
        i = int(bad[0])
        raise InputFileError(
            f"{_at(source, lines, i)}: column 't': {float(t[i]):.10g} s is not a "
            f"time (beyond ±{MAX_ABS_T_S:.0e} s, some 300 years)"
        )
    steps = np.diff(t)
    back = np.flatnonzero(steps <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise InputFileError(
            f"{_at(source, lines, i)}: column 't': {float(t[i])!r} s is not "
            f"after the previous {float(t[i - 1])!r} s"
        )
    jump = np.flatnonzero(steps > MAX_STEP_S)
    if jump.size:
        i = int(jump[0]) + 1
        raise InputFileError(
            f"{_at(source, lines, i)}: column 't' jumps {float(steps[i - 1]):.6g}"
            f" s after the previous row ({float(t[i - 1])!r} s), more than "
            f"{MAX_STEP_S:g} s: is t in seconds? (split a file holding two "
            "recordings)"
        )
    if t.size and t[-1] - t[0] > MAX_SPAN_S:
        i = int(np.searchsorted(t - t[0], MAX_SPAN_S, side="right"))
        raise InputFileError(
            f"{_at(source, lines, i)}: column 't': {float(t[i])!r} s is more "
            f"than a year after the first row ({float(t[0])!r} s)"
        )
    if steps.size == 0:
        return TimeBase(SAMPLE_PERIOD_S, resample=False)
    step = float(np.median(steps))
    if abs(step - SAMPLE_PERIOD_S) <= NOMINAL_TOLERANCE * SAMPLE_PERIOD_S:
        return TimeBase(step, resample=False)
    rate = 1.0 / step
    slack = 1e-6  # rows written to 1 us: 20 ms steps may read as 49.99999 Hz
    if rate < MIN_RATE_HZ * (1 - slack) or rate > MAX_RATE_HZ * (1 + slack):
        if rate < MIN_RATE_HZ:
            why = f"below {MIN_RATE_HZ:g} Hz, too slow to resample to {SAMPLE_RATE_HZ:g} Hz"
        else:
            why = f"above {MAX_RATE_HZ:g} Hz: is t in seconds?"
        raise InputFileError(
            f"{source}: column 't': rows every {_ms(step)} ({_hz(rate)}, "
            f"the median step), {why}; the contract's rows are 10 ms apart"
        )
    return TimeBase(step, resample=True)


def _ms(step_s: float) -> str:
    return f"{step_s * 1000:.4g} ms" if step_s < 10 else f"{step_s:.4g} s"


def _hz(rate_hz: float) -> str:
    return f"{rate_hz:.3g} Hz"


def held(name: str) -> bool:
    """Whether column ``name`` is held between rows when resampling (a command or operating
    condition: ``SpoolCmd``, ``Stick_SpoolCmd``, ``OilTemp``...) rather than interpolated."""
    return name.rsplit("_", 1)[-1] in COMMAND_NAMES


def resample(
    t: np.ndarray, columns: Mapping[str, np.ndarray], step_s: float
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Rows at ``step_s`` put on a 10 ms grid from the first row: pressures, flows and other
    measured columns linearly between the two rows around each instant, commands (``held``)
    at the last row at or before it; an interpolated value next to a missing sample is
    missing.  A step longer than ``GAP_PERIODS`` median steps is a gap: no grid row falls in
    it, and the grid restarts at the row after it, as a 100 Hz recording with that gap."""
    breaks = np.flatnonzero(np.diff(t) > GAP_PERIODS * step_s) + 1
    bounds = np.concatenate([[0], breaks, [t.size]])
    grids = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        n = int(np.floor((t[b - 1] - t[a]) / SAMPLE_PERIOD_S + 1e-9)) + 1
        grids.append(t[a] + np.arange(n) * SAMPLE_PERIOD_S)
    grid = np.concatenate(grids)
    # Per grid instant: the row at or before it, and how far towards the next row it lies.
    left = np.clip(np.searchsorted(t, grid + 1e-9, side="right") - 1, 0, t.size - 1)
    right = np.minimum(left + 1, t.size - 1)
    span = t[right] - t[left]
    frac = np.divide(grid - t[left], span, out=np.zeros_like(grid), where=span > 0)
    exact = frac <= 1e-9
    out: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        if held(name):
            out[name] = values[left]
        else:
            mixed = values[left] * (1.0 - frac) + values[right] * frac
            out[name] = np.where(exact, values[left], mixed)
    return grid, out


def resample_note(source: str, n_rows: int, step_s: float, n_out: int) -> str:
    """The one line that says a recording was resampled, and how."""
    return (
        f"{source}: {n_rows} rows every {_ms(step_s)} ({_hz(1 / step_s)}) resampled to "
        f"{n_out} rows at {SAMPLE_RATE_HZ:g} Hz (pressures and flows linear, commands "
        "held)"
    )
