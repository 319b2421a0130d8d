"""Decoded frames -> 100 Hz rows ``[t, SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp, PP, PA,
PB, QP, RodPos]`` on a sample clock, with staleness per signal.

The clock starts at the first frame fed and ticks every ``period_s`` (10 ms).  The row of
instant k holds, per signal, the latest value received at or before that instant, or NaN
when the signal is stale: its last value is older than ``stale_cycles`` (3) cycle times of
its message's GenMsgCycleTime (30 ms for 10 ms frames, 3 s for the 1 Hz oil temperature),
or it never arrived.  Stale data is a sensor fault downstream, never a hydraulic one.
Row ``t`` is seconds from the first row emitted (``start_time_s`` keeps its log time).

A start mid-operation (a daemon restart, a log cut from a longer one) meets each message at
some point of its own cycle: the 1 Hz oil temperature may come up to a second after the
first frame.  So the first rows are *warming*, not stale, and are not emitted, while a
required signal (every column but the ``optional`` ones, the rod sensor by default) has not
been seen and has not yet missed its own staleness time counted from the first frame
(``warm_row``).  The first row emitted is the first instant by which every required signal
was seen or is overdue: a signal that never comes is stale from its own deadline on (3 s for
the oil temperature), a sensor fault as before.  That row is t = 0: a recording starts
where it can be judged, and ``start_time_s`` is its log time (the first frame's plus the
warming rows).

Time that goes backwards (merged interfaces, a clock reset in the logger), forward gaps
and outages follow the rule of ``monitor.sampling.clock``: one kernel places each frame,
here frame by frame and in ``monitor.sampling.bulk`` over a whole log.

A silence of the whole bus of at least ``OUTAGE_S`` (1 s: a link down, a logger paused)
restarts every signal's staleness clock when frames return: a signal sent before it counts
as fresh again for its staleness time after the first frame back.  Without that, the 1 Hz
oil temperature, 3 s stale, would read as a failed sensor for up to a second after every
outage longer than 2 s, until its next frame.

Those rules still let a log ask for rows out of all proportion to its frames (a frame every
59.9 s is 6,000 rows each; a shuffled log resyncs the clock at every turn), so a log may need
at most ``row_limit(frames)`` rows: one hour, or 20 rows per frame of the log (a normal log
needs about 0.3).  More is refused before the rows are allocated (``too_many_rows``).

Rows always stay on one increasing 10 ms grid.  The sampler is fed incrementally
(``feed``) and hands out the rows that are complete (``advance``/``flush``), so the live
daemon and the offline replay share it.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.errors import InputFileError, NoHydraulicDataError
from monitor.sampling.clock import S_HELD, S_NEWEST, S_OFFSET, S_RESUMES, clock_step, new_state
from monitor.sampling.staleness import ON_SCHEDULE_CYCLES, deadline_row, fresh, warm_row
from monitor.signals import ROD_POS, SAMPLE_PERIOD_S, SIGNAL_NAMES

#: Row columns after ``t``: the contract signals, then the optional RodPos.
ROW_COLUMNS: tuple[str, ...] = (*SIGNAL_NAMES, ROD_POS.name)

_EPS_S = 1e-6  # log timestamps have 1 us resolution; absorbs float noise of t0 + k * period
_NAN = math.nan

#: A silence of every message this long is an outage: staleness restarts after it (s).
OUTAGE_S = 1.0

#: Rows any log may need: one hour at 100 Hz.
MIN_ROW_LIMIT = 360_000
#: Rows per frame of the log a longer one may need (a normal log needs about 0.3).
ROWS_PER_FRAME = 20


def row_limit(frames: int) -> int:
    """The most rows a log of ``frames`` frames may need."""
    return max(MIN_ROW_LIMIT, ROWS_PER_FRAME * frames)


def too_many_rows(
    path: str | Path, rows: int, frames: int, span_s: float, resyncs: int
) -> InputFileError:
    """The error for a log needing more than ``row_limit(frames)`` rows; ``span_s``: its
    hydraulic frames' log time from first to last, ``resyncs``: the clock resets followed."""
    if rows * SAMPLE_PERIOD_S > 2 * span_s + 3600:  # far more time than the log spans
        why = f"its clock jumps back and forth ({resyncs} resyncs): fix or sort its timestamps"
    else:
        why = "it is long and sparse: split it into pieces"
    return InputFileError(
        f"{path}: would need {rows} rows of {SAMPLE_PERIOD_S * 1000:g} ms for {frames} frames"
        f" spanning {span_s:.1f} s of log time, more than the limit of {row_limit(frames)}"
        f" (an hour, or {ROWS_PER_FRAME} per frame); {why}"
    )


#: Share of a log's frames that may be older than the newest before them (jitter of merged
#: interfaces stays far below; a reversed log has them all, some replayed twice).
MAX_BACKWARDS_SHARE = 0.75


def runs_backwards(path: str | Path, frames: int, counts: dict[str, Any]) -> InputFileError | None:
    """The error for a log whose clock runs backwards (a reversed log): more than
    ``MAX_BACKWARDS_SHARE`` of its ``frames`` fed to the clock older than the newest one
    before them.  Its clock would resync every few frames and its counters jump at every
    frame; like a shuffled log, it is refused rather than judged."""
    back = int(counts["time_backwards"])
    if back <= MAX_BACKWARDS_SHARE * frames:
        return None
    return InputFileError(
        f"{path}: its clock runs backwards: {back} times a frame older than the newest before"
        f" it, for {frames} frames ({counts['time_resyncs']} resyncs); a reversed log? fix or"
        " sort its timestamps"
    )


@dataclass
class TimeCounts:
    """How often the sampler had to deal with a misbehaving clock."""

    time_backwards: int = 0  # frames older than the newest one (jitter or skipped)
    time_skipped: int = 0  # of those, frames dropped
    time_resyncs: int = 0  # clock resets followed
    gaps_shortened: int = 0  # forward gaps longer than max_gap_s

    def as_dict(self) -> dict[str, int]:
        return dict(vars(self))


@dataclass(frozen=True)
class RowSpec:
    """The rows a sampler makes: their columns on a clock of ``period_s``, each column's
    staleness, the columns warming waits for (and the row each must be seen by), and the
    clock's limits (``monitor.sampling.clock``)."""

    columns: tuple[str, ...]
    period_s: float
    max_gap_s: float
    resync_frames: int
    index: dict[str, int]  # column name -> its position
    stale_s: tuple[float, ...]  # per column: a value older than this is stale
    on_schedule_s: tuple[float, ...]  # per column: on schedule when this near the newest frame
    required: tuple[int, ...]  # the columns that are not optional
    deadline_rows: tuple[int, ...]  # per required column: the row it is stale by, unseen

    @classmethod
    def build(
        cls,
        cycle_times_s: Mapping[str, float],
        columns: tuple[str, ...],
        period_s: float,
        stale_cycles: float,
        max_gap_s: float,
        resync_frames: int,
        optional: Collection[str],
    ) -> RowSpec:
        columns, period_s = tuple(columns), float(period_s)
        cycle_s = [cycle_times_s.get(c, period_s) for c in columns]
        stale_s = tuple(stale_cycles * c + _EPS_S for c in cycle_s)
        on_schedule_s = tuple(ON_SCHEDULE_CYCLES * c + _EPS_S for c in cycle_s)
        required = tuple(i for i, c in enumerate(columns) if c not in set(optional))
        return cls(
            columns,
            period_s,
            float(max_gap_s),
            int(resync_frames),
            {name: i for i, name in enumerate(columns)},
            stale_s,
            on_schedule_s,
            required,
            tuple(deadline_row(stale_s[i], period_s) for i in required),
        )


class Sampler:
    """Turns (timestamp, message, physical values) into rows on a fixed sample clock."""

    def __init__(
        self,
        cycle_times_s: Mapping[str, float],
        columns: tuple[str, ...] = ROW_COLUMNS,
        period_s: float = SAMPLE_PERIOD_S,
        stale_cycles: float = 3.0,
        max_gap_s: float = 60.0,
        resync_frames: int = 5,
        optional: Collection[str] = (ROD_POS.name,),
    ) -> None:
        """``cycle_times_s`` maps a signal to its message's cycle time (s); a signal not
        in it is stale after ``stale_cycles`` sample periods.  ``optional`` columns (a
        sensor a machine may lack) do not hold the first rows back while warming."""
        self.spec = RowSpec.build(
            cycle_times_s, columns, period_s, stale_cycles, max_gap_s, resync_frames, optional
        )
        self._warming = True  # no row emitted yet: the first ones may be warming
        self._values = np.full(len(self.columns), _NAN)
        self._last_t = np.full(len(self.columns), -math.inf)  # sampler time of each value
        self.seen: set[str] = set()
        self.first_time_s: float | None = None  # log time of the first frame (sampler time 0)
        self.start_time_s: float | None = None  # log time of row t = 0 (once warming ends)
        self.origin_k = 0  # the instant of row t = 0 (warming rows are not emitted)
        self._state, self._counts = new_state(0.0)  # the clock (monitor.sampling.clock)
        self._resumed = -math.inf  # sampler time of the first frame after the last outage
        self._k = 0  # next instant to emit
        self._pending: list[list[float]] = []
        self._behind: list[tuple[float, str, Mapping[str, float]]] = []

    @property
    def columns(self) -> tuple[str, ...]:
        return self.spec.columns

    @property
    def period_s(self) -> float:
        return self.spec.period_s

    @property
    def max_gap_s(self) -> float:
        return self.spec.max_gap_s

    @property
    def counts(self) -> TimeCounts:
        """How often the clock had to deal with a misbehaving log time so far."""
        return TimeCounts(*(int(c) for c in self._counts))

    @classmethod
    def for_codec(cls, codec: FrameCodec, **kwargs: Any) -> Sampler:
        """A sampler whose staleness follows the GenMsgCycleTime of ``codec``'s DBC;
        ``kwargs`` as for ``Sampler``."""
        return cls(codec.signal_cycle_times(), **kwargs)

    @property
    def started(self) -> bool:
        """Whether a frame has been fed (the clock runs)."""
        return self.first_time_s is not None

    @property
    def pending(self) -> int:
        """Number of completed rows waiting in ``take``."""
        return len(self._pending)

    @property
    def rows(self) -> int:
        """Rows emitted so far (handed out or pending)."""
        return self._k

    @property
    def width(self) -> int:
        return 1 + len(self.spec.columns)

    # -- feeding --------------------------------------------------------------------------

    def feed(self, timestamp_s: float, message_name: str, values: Mapping[str, float]) -> None:
        """Apply one decoded frame (log/bus time in s).  Signals not in ``columns`` are
        ignored; ``message_name`` is only used for bookkeeping."""
        if self.first_time_s is None:
            self.first_time_s = float(timestamp_s)
            self._state, self._counts = new_state(float(timestamp_s))  # sampler time 0
        state, spec = self._state, self.spec
        st = clock_step(
            float(timestamp_s),
            state,
            self._counts,
            spec.period_s,
            spec.max_gap_s,
            spec.resync_frames,
            _EPS_S,
            OUTAGE_S,
        )
        if st != st:  # held back as possibly older
            self._behind.append((timestamp_s, message_name, values))
            if state[S_HELD] == 0:  # a clock reset: replay them on the new time base
                frames, self._behind = self._behind, []
                for ts, name, vals in frames:
                    self.feed(ts, name, vals)
            return
        del self._behind[int(state[S_HELD]) :]  # strays dropped by the clock
        self._emit_before(st)
        if state[S_RESUMES]:  # the rows of the silence are out: staleness restarts
            self._resumed = st
        self._apply(st, values)

    def _apply(self, st: float, values: Mapping[str, float]) -> None:
        index = self.spec.index
        for name, value in values.items():
            i = index.get(name)
            if i is not None:
                self._values[i] = float(value)
                self._last_t[i] = st
                self.seen.add(name)

    # -- rows -----------------------------------------------------------------------------

    def _emit_before(self, st: float) -> None:
        """Queue the rows of instants strictly before sampler time ``st``."""
        end = math.ceil((st - _EPS_S) / self.spec.period_s)  # first instant >= st - eps
        self._emit_to(end)

    def _emit_to(self, end: int) -> None:
        k0 = self._k
        if end <= k0:
            return
        if self._warming:  # skip the warming rows (their frames are all applied by now)
            seen = [0 if self._last_t[i] > -math.inf else math.inf for i in self.spec.required]
            k0 = min(max(k0, warm_row(seen, self.spec.deadline_rows)), end)
            self._warming = k0 == end
            if not self._warming:
                self.origin_k = k0
                self.start_time_s = self.first_time_s + k0 * self.period_s  # type: ignore[operator]
        # The state is the same for every row of [k0, end): no frame lies between them.
        inst = np.arange(k0, end) * self.period_s
        last = self._last_t
        ok = fresh(
            inst[:, None],
            last[None, :],
            last.max(),
            self._resumed,
            self.spec.stale_s,
            self.spec.on_schedule_s,
        )
        t = np.arange(k0 - self.origin_k, end - self.origin_k) * self.period_s
        block = np.column_stack([t, np.where(ok, self._values[None, :], np.nan)])
        self._pending.extend(block.tolist())
        self._k = end

    def take(self) -> np.ndarray:
        """Rows completed so far (instants before the newest frame), not handed out yet."""
        rows, self._pending = self._pending, []
        if not rows:
            return np.empty((0, self.width))
        return np.array(rows, dtype=np.float64)

    def advance(self, until_s: float) -> np.ndarray:
        """Rows (n x (1 + len(columns))) of every instant up to log/bus time ``until_s``
        not handed out yet.  Call it with a time no frame of an earlier instant can still
        arrive before (the live daemon allows for bus latency)."""
        if self.started:
            st = until_s + self._state[S_OFFSET]
            self._emit_to(math.floor((st + _EPS_S) / self.period_s) + 1)
        return self.take()

    def flush(self) -> np.ndarray:
        """Rows up to and including the instant of the newest frame (end of a log)."""
        if self.started:
            self._emit_to(math.floor((self._state[S_NEWEST] + _EPS_S) / self.period_s) + 1)
        return self.take()


def hydraulic_messages(codec: FrameCodec, columns: tuple[str, ...] = ROW_COLUMNS) -> set[str]:
    """Names of the DBC messages that carry at least one row signal."""
    wanted = set(columns)
    return {info.name for info in codec.messages.values() if wanted.intersection(info.signal_names)}


def no_hydraulic_data(path: str | Path, counts: Mapping[str, Any]) -> NoHydraulicDataError:
    """The error (exit 3) for a log without one valid hydraulic frame, with its counts."""
    rejected = ", ".join(f"{k} {v}" for k, v in counts["rejected"].items() if v)
    return NoHydraulicDataError(
        f"{path}: {counts['frames']} frames read, none of them a valid hydraulic frame"
        f" of the DBC ({counts['ignored']} with unknown ids"
        + (f"; rejected: {rejected}" if rejected else "")
        + ")"
    )


_ID_MASK_EXT = 0x1FFFFFFF
_ID_MASK_STD = 0x7FF


def sensor_filters(
    codec: FrameCodec, columns: tuple[str, ...] = ROW_COLUMNS
) -> list[dict[str, int | bool]]:
    """python-can filters passing exactly the DBC's frames of the row ``columns`` (sensor
    and command frames, not our own MON_*)."""
    out: list[dict[str, int | bool]] = []
    for name in sorted(hydraulic_messages(codec, columns)):
        info = codec.messages[name]
        mask = _ID_MASK_EXT if info.is_extended_id else _ID_MASK_STD
        out.append({"can_id": info.frame_id, "can_mask": mask, "extended": info.is_extended_id})
    return out
