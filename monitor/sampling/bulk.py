"""A candump log to a 100 Hz ``Recording`` in bulk: the offline path of ``monitor detect``.

The rows the daemon's ``Sampler`` makes of the same frames fed one by one (tests hold it
equal to that frame-by-frame reference, ``tests/naive_frames.py``), computed in three array passes:

1. ``read_candump_frames``: the log as arrays of frames (``monitor.io.candump_bulk``);
2. ``decode_frames``: checks and physical values per message ID (``monitor.codec.bulk``);
3. the sample clock.  Its time rules (``monitor.sampling.clock``) depend on every frame
   before, so a small serial numba kernel runs the sampler's own step kernel, ``clock_step``,
   over the frames and gives each applied frame its sampler time st.  Applied times never
   decrease, and a frame is visible from row ``K = max over frames so far of
   ceil((st - eps) / period)`` on (the rows the sampler emits before applying it), so each
   signal's value in row k is that of its last frame with K <= k (one ``searchsorted``), or
   NaN when older than its staleness (the sampler's rule, ``monitor.sampling.staleness``:
   counted from the end of the last outage when that is later, and from the bus's newest
   frame for a signal on schedule when the bus went quiet).

The kernel uses plain IEEE arithmetic (no fast-math), so every time is the float the
frame-by-frame sampler computes.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from pathlib import Path

import numpy as np

from monitor.codec.bulk import DecodedMessage, decode_frames
from monitor.codec.frames import FrameCodec
from monitor.io.candump_bulk import read_candump_frames
from monitor.io.recording import Recording
from monitor.jit import jit
from monitor.sampling.clock import N_STATE, S_HELD, S_NEWEST, S_OFFSET, S_RESUMES, clock_step
from monitor.sampling.sampler import (
    _EPS_S,
    OUTAGE_S,
    ROW_COLUMNS,
    Sampler,
    TimeCounts,
    hydraulic_messages,
    no_hydraulic_data,
    row_limit,
    runs_backwards,
    too_many_rows,
)
from monitor.sampling.staleness import fresh, warm_row
from monitor.signals import ROD_POS


@jit(aot=True, fastmath=False)
def _clock(ts, period, max_gap, resync, eps, outage):  # pragma: no cover - numba
    """``clock_step`` over every frame: the sampler time of each (NaN: skipped), the applied
    frames in application order, whether each ended an outage, the counts and the newest
    time.  Held frames are replayed through a stack in the order ``Sampler.feed`` replays
    them."""
    n = ts.shape[0]
    st_out = np.full(n, np.nan)
    order = np.empty(n + 1, np.int64)  # applied frames in application order
    resumes = np.zeros(n + 1, np.bool_)
    n_applied = 0
    behind = np.empty(resync, np.int64)
    nb = 0
    stack = np.empty(2 * resync + 2, np.int64)
    state = np.zeros(N_STATE)
    state[S_OFFSET] = -ts[0]
    state[S_NEWEST] = -np.inf
    counts = np.zeros(4, np.int64)
    for f0 in range(n):
        sp = 1
        stack[0] = f0
        while sp > 0:
            sp -= 1
            f = stack[sp]
            st = clock_step(ts[f], state, counts, period, max_gap, resync, eps, outage)
            if st != st:  # held back
                behind[nb] = f
                nb += 1
                if state[S_HELD] == 0:  # a resync: replay them in order
                    if sp + nb > stack.shape[0]:
                        grown = np.empty(stack.shape[0] * 2, np.int64)
                        grown[:sp] = stack[:sp]
                        stack = grown
                    for k in range(nb - 1, -1, -1):
                        stack[sp] = behind[k]
                        sp += 1
                    nb = 0
                continue
            nb = np.int64(state[S_HELD])  # strays dropped by the clock
            st_out[f] = st
            if n_applied == order.shape[0]:
                grown = np.empty(order.shape[0] * 2, np.int64)
                grown[:n_applied] = order
                order = grown
                grown_r = np.zeros(resumes.shape[0] * 2, np.bool_)
                grown_r[:n_applied] = resumes
                resumes = grown_r
            order[n_applied] = f
            resumes[n_applied] = state[S_RESUMES] != 0.0
            n_applied += 1
    return st_out, order[:n_applied], resumes[:n_applied], counts, state[S_NEWEST]


def recording_from_candump_bulk(
    path: str | Path,
    codec: FrameCodec | None = None,
    columns: tuple[str, ...] = ROW_COLUMNS,
    optional: Collection[str] = (ROD_POS.name,),
) -> Recording:
    """A candump log as a 100 Hz ``Recording`` (RodPos only when the log has it): the rows
    of ``Sampler``, frame by frame, computed in bulk.

    ``meta["counts"]`` holds the log's frame counts: frames read, decoded, ignored (unknown
    id), rejected by reason, counter jumps, and the sampler's time counts.  Raises
    ``InputFileError`` for a malformed line or a log needing more than ``row_limit(frames)``
    rows, and ``NoHydraulicDataError`` (exit 3) when no valid hydraulic frame of the DBC is
    in the log.  ``columns`` and ``optional`` as for ``Sampler``."""
    codec = codec or FrameCodec.from_dbc()
    # Its parameters, staleness and warming rows, not its feed().
    sampler = Sampler.for_codec(codec, columns=columns, optional=optional)
    frames = read_candump_frames(path)
    decoded = decode_frames(codec, frames)
    wanted = hydraulic_messages(codec, columns)
    hydraulic = [name for name in codec.messages if name in wanted]
    parts = [decoded[name] for name in hydraulic if decoded[name].rows.size]
    counts = codec.counts.as_dict()
    if not parts:
        raise no_hydraulic_data(path, counts)
    # The frames the sampler is fed, in log order, and per frame its message's slot.
    rows = np.concatenate([p.rows for p in parts])
    msg_of = np.concatenate([np.full(p.rows.size, k) for k, p in enumerate(parts)])
    pos_in_msg = np.concatenate([np.arange(p.rows.size) for p in parts])
    by_time = np.argsort(rows, kind="stable")
    rows, msg_of, pos_in_msg = rows[by_time], msg_of[by_time], pos_in_msg[by_time]
    ts = np.ascontiguousarray(frames.timestamp[rows])
    period = sampler.period_s
    st, applied, resumes, tc, newest = _clock(
        ts, period, sampler.max_gap_s, sampler.spec.resync_frames, _EPS_S, OUTAGE_S
    )
    # Rows emitted before each applied frame: a running maximum over application order.
    first_row = np.maximum.accumulate(np.ceil((st[applied] - _EPS_S) / period)).astype(np.int64)
    n_rows = max(int(first_row[-1]), math.floor((newest + _EPS_S) / period) + 1)
    if n_rows > row_limit(len(frames)):  # before a row is allocated
        raise too_many_rows(path, n_rows, len(frames), float(ts.max() - ts.min()), int(tc[2]))
    time_counts = TimeCounts(*(int(v) for v in tc))
    if err := runs_backwards(path, ts.size, time_counts.as_dict()):
        raise err
    cols, first_seen = _columns(
        sampler, parts, (msg_of, pos_in_msg), applied, first_row, st, resumes, n_rows
    )
    warm = min(
        warm_row(first_seen[list(sampler.spec.required)], sampler.spec.deadline_rows), n_rows
    )
    # Row t = 0 is the first one past warming; its log time as the sampler computes it.
    start = float(ts[0]) + warm * period if warm < n_rows else None
    meta: dict[str, object] = {
        "format": "candump",
        "start_time_s": start,
        "counts": {**counts, **time_counts.as_dict()},
    }
    cols = {name: col[warm:] for name, col in cols.items()}
    return Recording(t=np.arange(n_rows - warm) * period, columns=cols, source=str(path), meta=meta)


def _columns(
    sampler: Sampler,
    parts: list[DecodedMessage],
    slots: tuple[np.ndarray, np.ndarray],
    applied: np.ndarray,
    first_row: np.ndarray,
    st: np.ndarray,
    resumes: np.ndarray,
    n_rows: int,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Each signal's rows (the value of its last frame visible by then, NaN once stale) and
    the row from which each is visible (inf: never); ``slots``: per frame its message's
    index in ``parts`` and its position there."""
    msg_of, pos_in_msg = slots
    inst = np.arange(n_rows) * sampler.period_s
    # Outages (the clock's rule): from the first row after each, staleness restarts at the
    # time of the frame that ended it (the sampler's ``_resumed``).
    st_applied = st[applied]
    ends = np.flatnonzero(resumes)
    back_at = np.searchsorted(first_row[ends], np.arange(n_rows), side="right") - 1
    resumed = np.append(st_applied[ends], -np.inf)[back_at]  # -1: no outage yet, -inf
    # The newest frame visible at each row (applied times never decrease).
    visible = np.searchsorted(first_row, np.arange(n_rows), side="right") - 1
    newest = np.append(st_applied, -np.inf)[visible]
    seen: set[str] = set()
    first_seen = np.full(len(sampler.columns), np.inf)  # row from which each is visible
    columns: dict[str, np.ndarray] = {}
    stale = dict(zip(sampler.columns, sampler.spec.stale_s, strict=True))
    on_schedule = dict(zip(sampler.columns, sampler.spec.on_schedule_s, strict=True))
    for name in sampler.columns:
        carriers = [k for k, p in enumerate(parts) if name in p.values]
        sel = np.flatnonzero(np.isin(msg_of[applied], carriers))
        col = np.full(n_rows, np.nan)
        if sel.size:
            seen.add(name)
            first_seen[sampler.columns.index(name)] = first_row[sel[0]]
            f = applied[sel]
            vals = np.empty(sel.size)
            for k in carriers:
                mine = msg_of[f] == k
                vals[mine] = parts[k].values[name][pos_in_msg[f[mine]]]
            last = np.searchsorted(first_row[sel], np.arange(n_rows), side="right") - 1
            have = last >= 0
            li = last[have]
            ok = fresh(
                inst[have], st[f[li]], newest[have], resumed[have], stale[name], on_schedule[name]
            )
            col[np.flatnonzero(have)[ok]] = vals[li[ok]]
        if name != ROD_POS.name or name in seen:
            columns[name] = col
    return columns, first_seen
