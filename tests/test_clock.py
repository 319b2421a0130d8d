"""The sample clock's step kernel (monitor.sampling.clock) against the recursive twin written
from its rule in tests/naive_frames.py, on log times that misbehave in every way the rule names."""

from __future__ import annotations

import math

import naive_frames
import numpy as np
import pytest

from monitor.sampling.bulk import _clock
from monitor.sampling.clock import S_HELD, clock_step, new_state
from monitor.sampling.sampler import _EPS_S, OUTAGE_S

PERIOD, MAX_GAP, RESYNC = 0.01, 60.0, 5


def _hostile_times(seed: int, n: int = 3000) -> np.ndarray:
    """Log times at 2.5 ms steps with jitter, strays, clock resets, outages and long gaps."""
    rng = np.random.default_rng(seed)
    t, out = 1_700_000_000.0, []
    for _ in range(n):
        r = rng.random()
        if r < 0.05:
            out.append(t - rng.uniform(0, PERIOD))  # jitter
        elif r < 0.08:
            out.append(t - rng.uniform(0.05, 5.0))  # a stray
        elif r < 0.085:
            t -= rng.uniform(1.0, 100.0)  # the logger's clock reset
            out.append(t)
        elif r < 0.09:
            t += rng.choice([rng.uniform(1.0, 3.0), rng.uniform(61.0, 1e5)])  # outage, gap
            out.append(t)
        else:
            t += 0.0025
            out.append(t)
    return np.round(np.array(out), 6)


def _step_all(ts: np.ndarray) -> tuple[np.ndarray, list[int], list[bool], list[int]]:
    """``clock_step`` driven frame by frame as ``Sampler.feed`` drives it."""
    state, counts = new_state(float(ts[0]))
    st_out = np.full(ts.size, np.nan)
    order: list[int] = []
    resumes: list[bool] = []
    held: list[int] = []

    def feed(f: int) -> None:
        st = clock_step(float(ts[f]), state, counts, PERIOD, MAX_GAP, RESYNC, _EPS_S, OUTAGE_S)
        if math.isnan(st):
            held.append(f)
            if state[S_HELD] == 0:
                replay = held[:]
                held.clear()
                for g in replay:
                    feed(g)
            return
        del held[int(state[S_HELD]) :]
        st_out[f] = st
        order.append(f)
        resumes.append(bool(state[4]))

    for f in range(ts.size):
        feed(f)
    return st_out, order, resumes, [int(c) for c in counts]


@pytest.mark.parametrize("seed", range(6))
def test_step_kernel_frame_by_frame_and_in_bulk_match_the_rule(seed: int) -> None:
    ts = _hostile_times(seed)
    want_st, want_order, want_resumes, want_counts = naive_frames.sample_clock(
        ts, PERIOD, MAX_GAP, RESYNC, _EPS_S, OUTAGE_S
    )
    assert min(want_counts) > 0, "every rule exercised"
    st, order, resumes, counts = _step_all(ts)
    np.testing.assert_array_equal(st, want_st)  # bit for bit, NaN where skipped
    assert order == want_order.tolist() and resumes == want_resumes.tolist()
    assert counts == want_counts
    b_st, b_order, b_resumes, b_counts, b_newest = _clock(
        ts, PERIOD, MAX_GAP, RESYNC, _EPS_S, OUTAGE_S
    )
    np.testing.assert_array_equal(b_st, want_st)
    assert b_order.tolist() == want_order.tolist()
    assert b_resumes.tolist() == want_resumes.tolist()
    assert b_counts.tolist() == want_counts and b_newest == want_st[want_order[-1]]
