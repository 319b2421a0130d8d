"""The sample clock's time rule for one frame: one numba kernel, ``clock_step``, called per
frame by the live ``Sampler.feed`` and in a loop over a whole log by the bulk path
(``monitor.sampling.bulk``), so live and offline place every frame by the same code.

Time that goes backwards (merged interfaces, a clock reset in the logger) must not break
the clock.  The rule, for a frame at log time ``ts`` (sampler time ``st = ts + offset``):

* a frame at most one sample period older than the newest frame is reordering jitter and
  is applied at the newest frame's time;
* an older frame is held back, and dropped (counted as skipped) when a frame on time
  follows, unless ``resync`` consecutive frames are all older: then the logger's clock was
  reset, and the offset shifts so that the first held frame lands one period after the
  newest one; the caller replays the held frames in order (a resync);
* a forward gap longer than ``max_gap`` is shortened to ``max_gap`` (a clock jump of days
  cannot allocate millions of rows);
* a frame at least ``outage`` after the newest one ends an outage (the whole bus silent):
  staleness restarts at it (the caller applies that after the rows before it are out).

The state lives in two small arrays the caller owns (``new_state``), so a step allocates
nothing.  Plain IEEE arithmetic (no fast-math): both sides compute the very same floats.
"""

from __future__ import annotations

import numpy as np

from monitor.jit import jit

#: Indices of the float state vector.
S_OFFSET = 0  # sampler time = log time + offset
S_NEWEST = 1  # sampler time of the newest frame applied (-inf before the first)
S_HELD = 2  # frames held back as possibly older (0 after a resync or a frame on time)
S_HELD_TS = 3  # log time of the first held frame
S_RESUMES = 4  # 1.0 when the last applied frame ended an outage
N_STATE = 5
#: Indices of the count vector (``TimeCounts`` order).
C_BACKWARDS, C_SKIPPED, C_RESYNCS, C_GAPS = range(4)


def new_state(first_ts: float) -> tuple[np.ndarray, np.ndarray]:
    """(state, counts) of a clock whose sampler time 0 is log time ``first_ts``."""
    state = np.zeros(N_STATE)
    state[S_OFFSET] = -first_ts
    state[S_NEWEST] = -np.inf
    return state, np.zeros(4, np.int64)


@jit(aot=True, fastmath=False)
def clock_step(ts, state, counts, period, max_gap, resync, eps, outage):  # pragma: no cover
    """Sampler time of a frame at log time ``ts`` (s), or NaN when it is held back.

    After a NaN, ``state[S_HELD] == 0`` means a resync: the caller replays the held frames
    (this one last) through ``clock_step`` in order.  After a time, the caller keeps only
    the first ``state[S_HELD]`` held frames (the others were strays, counted as skipped).
    """
    st = ts + state[S_OFFSET]
    newest = state[S_NEWEST]
    if st < newest - eps:
        counts[C_BACKWARDS] += 1
        if newest - st <= period:
            st = newest  # reordering jitter
        else:
            held = state[S_HELD]
            if held == 0:
                state[S_HELD_TS] = ts
            held += 1
            if held < resync:
                state[S_HELD] = held
                return np.nan
            # Clock reset: the first held frame continues right after the newest one.
            state[S_OFFSET] = newest + period - state[S_HELD_TS]
            state[S_HELD] = 0
            counts[C_RESYNCS] += 1
            return np.nan
    elif state[S_HELD] > 0:
        counts[C_SKIPPED] += np.int64(state[S_HELD])  # strays, not a clock reset
        state[S_HELD] = 0
    if newest > -np.inf and st - newest > max_gap:
        state[S_OFFSET] -= st - newest - max_gap
        st = newest + max_gap
        counts[C_GAPS] += 1
    state[S_RESUMES] = 1.0 if st - newest >= outage else 0.0
    state[S_NEWEST] = st
    return st
