"""A small valve deadband read from the flows at held commands (``judge/heldflow.py``,
``diagnose/deadband.py``), where the openings and closings cannot time it.

Expected values by hand: the simulator's overlap ``o`` opens a held command ``A`` (% stroke)
``(A - o) / (100 - o)`` of the valve instead of ``A / 100``, so where the valve sets the flow
it falls short by ``o (100 - A) / ((100 - o) A)``.  Against a hypothesis of 10 % the held
levels bear out ``(6 / 94) / (10 / 90)`` of its shortfall under a true 6 % overlap: the held
flows read 10 x 0.574 = 5.7 %.  Commands stepped (the ``step`` cycle) cross any overlap
within one sample, so the openings are not later than the closings.  Every reading 20 ms
late moves no settled flow: the held flows read no overlap.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from monitor.gap.data.prepare import prepare
from monitor.gap.data.segments import make_segments
from monitor.gap.judge import heldflow, onsets
from monitor.io.recording import Recording
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

M = load_machine()


def _step(overlap_pct: float = 0.0, seconds: float = 90.0) -> Recording:
    cmd = make_cycle("step", seconds, 5)
    effects = [Effect.make("valve_deadband", overlap_pct=overlap_pct)] if overlap_pct else []
    return simulate(cmd, M, effects=effects, seed=5)


@pytest.fixture(scope="module")
def stepped():
    base = prepare(_step(), M)
    return {
        "base": base,
        "segments": make_segments(base),
        "six": prepare(_step(6.0), M).meas,
        "ten": prepare(_step(10.0), M).meas,
    }


def test_held_flows_read_a_small_overlap_the_timing_cannot(stepped):
    base, segs = stepped["base"], stepped["segments"]
    got = heldflow.measure(
        replace(base, meas=stepped["six"]),
        segs,
        base.meas,
        stepped["ten"],
        10.0,
    )
    assert got is not None and got.levels >= heldflow.MIN_LEVELS
    assert got.overlap_pct == pytest.approx(10.0 * (6 / 94) / (10 / 90), abs=1.0)
    assert got.share >= 0.95
    # A step crosses the overlap within a sample: the openings are not clearly later.
    timed = onsets.measure(base, segs, base.meas, meas=stepped["six"])
    assert timed is None or timed.apart_share < 0.95


def test_a_shared_delay_moves_no_held_flow(stepped):
    base, segs = stepped["base"], stepped["segments"]
    late = {k: np.concatenate([np.full(2, v[0]), v[:-2]]) for k, v in base.meas.items()}
    got = heldflow.measure(replace(base, meas=late), segs, base.meas, stepped["ten"], 10.0)
    assert got is not None
    assert abs(got.overlap_pct) < 1.0 and got.share == 0.0
