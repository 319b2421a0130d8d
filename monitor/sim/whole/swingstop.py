"""The ``swing-stop`` training cycle: short, fast swings let go to centre at once, as an
operator nudges the house to line the bucket up, with the neighbours' levers let go around
the same moment.

Let go in a few tenths of a second, the swing's spool closes both motor ports while the
house still turns: the house brakes on its crossover reliefs and rings on the trapped oil
(on the simulated machine, 86 % for 2.4 s let go in 0.4 s: the motor's ports swing 0 -> 142
and 8 -> 105 bar within a second and settle at 75 bar over 3 s).  Mixed work stops the
swing like that in every truck load, but how hard it rings depends on what else lets go at
that moment: a boom let go with the swing puts the pump at standby mid-brake, the meter-in
starves and the house rings higher than any stop of the hour the swing's model was fitted
on, which then predicted the ringing at half its amplitude (kernel support 0.00-0.14) and
its bias statistic alarmed on a normal run (docs/benchmarks.md, the swing's quick stops).

So each block here runs a few swings at 40-100 % of lever for ``RUN_S``, let go over
``RELEASE_S`` (never faster than the operator's rate limit), and in most of them lets a
neighbour's lever go ``NEIGHBOUR_OFFSET_S`` from the swing's; the house rests ``PAUSE_S``
before the next (from the ringing's middle to well after it has settled).  Between blocks
a truck load, and now and then a lift, keep the other states in the data.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the operator lives in cycles, which dispatches here
    from monitor.sim.whole.cycles import _Operator

#: Swing lever while it runs, % of full.
AMP_PCT = (40.0, 100.0)
#: How long the swing lever is held before it is let go, s.
RUN_S = (0.8, 3.5)
#: How long the lever takes back to centre, s (the rate limit of 200 %/s makes 0.2-0.5 s
#: the floor from 40-100 %).
RELEASE_S = (0.2, 0.6)
#: The house at rest before the next quick swing, s.
PAUSE_S = (0.6, 6.0)
#: Quick swings in a block.
BLOCK = (3, 9)
#: Share of quick swings with a neighbour's lever let go near the swing's.
NEIGHBOUR_SHARE = 0.7
#: When that neighbour's lever is let go, s after the swing's lever starts back.
NEIGHBOUR_OFFSET_S = (-0.6, 0.6)


def quick_swing(op: _Operator, start: float) -> float:
    """One quick swing from ``start``, let go to centre; return when its lever is back."""
    r = op.rng
    amp = r.uniform(*AMP_PCT) * (1 if r.random() < 0.5 else -1)
    run = r.uniform(*RUN_S)
    release = max(r.uniform(*RELEASE_S), abs(amp) / 200.0)
    held = op._span(start, run)
    op.spool["swing"][held] = amp
    ramp = op._span(start + run, release)
    k = ramp.stop - ramp.start
    if k > 0:
        op.spool["swing"][ramp] = amp * (1.0 - (1.0 + np.arange(k)) / k)
    if r.random() < NEIGHBOUR_SHARE:
        _neighbour(op, start, start + run + r.uniform(*NEIGHBOUR_OFFSET_S))
    return start + run + release


def _neighbour(op: _Operator, swing_start: float, let_go: float) -> None:
    """A boom, stick or bucket move let go at ``let_go``, started with the swing or up to
    2 s before it."""
    r = op.rng
    loop = str(r.choice(["boom", "boom", "stick", "bucket"]))
    start = max(0.0, min(swing_start - r.uniform(0.0, 2.0), let_go - 0.3))
    amp = r.uniform(25.0, 90.0)
    # Mostly lowering the boom (the return), else either way within the stroke.
    frac = op.pos[loop] / op.m.stroke_m(loop)
    sign = -1.0 if (loop == "boom" and r.random() < 0.7) or frac > 0.7 else 1.0
    if frac < 0.15:
        sign = 1.0
    op.spool[loop][op._span(start, let_go - start)] = sign * amp
    area = op.m.area_a_m2(loop) if sign > 0 else op.m.area_b_m2(loop)
    travel = amp / 100.0 * op.m.rated_flow_m3_s(loop) / area * (let_go - start)
    op.pos[loop] = float(min(max(op.pos[loop] + sign * travel, 0.0), op.m.stroke_m(loop)))


def swing_stops(op: _Operator) -> None:
    """One truck load, then a block of quick swings; after one block in four, a lift."""
    op.truck_loading()
    r = op.rng
    t = op.t
    for _ in range(int(r.integers(*BLOCK))):
        t = quick_swing(op, t + r.uniform(*PAUSE_S))
    op.t = t + r.uniform(*PAUSE_S)
    if r.random() < 0.25:
        op.lifting()
