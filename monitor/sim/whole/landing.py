"""The ``rest-on-stop`` training cycle's boom lever let go as an operator lets it go: on
feeling the rod land on its bottom stop, after a reaction time.

The duty cycles are open-loop: the operator's idea of a rod's position drifts from the
simulated one, so a lever released at an estimated landing lands the rod seconds early or
not at all.  What the boom's model must see is the release at every moment around the real
landing, because the moment sets what the rod side traps for as long as the boom rests
there: closed as the rod lands, it keeps its lowering pressure (10-40 bar); a tenth of a
second later it has risen towards the stall pressure (150-200 bar).  Mixed work lets the
lever go near a landing now and then (its moves are timed by eye), and the boom then rests
on its stop with 15-70 bar on the rod side while the next dig runs: a model fitted on an
hour of mixed work had seen that a few seconds in all and predicted the boom rising there,
10-13 bar a step (docs/benchmarks.md, the boom's bias statistic at rest on its stop).

So the cycle holds the lever past its estimated landing (``cycles.REST_HOLD_S``), and this
module simulates the machine with every lever held on, finds where the rod lands in each
lowering and starts the lever's return before it by a share of the return's time drawn from
``RELEASE_EARLY``.  The window is narrow and scales with that time (the lever's travel at the
operator's rate limit, 0.1-0.45 s from 20-90 %): on the simulated machine, lowering at
45 % (a 0.225 s return), a return started 0.6 of it before the landing stops the rod 2 mm
short (the boom then hangs on its cap side: a hold), 0.5-0.2 of it before traps 28-161 bar,
0.1 the stall (194 bar); at 70 %, 0.5 stops it short, 0.45-0.35 traps 66-182 bar.  The
later moves start from the stop whether the rod rested on it or stopped just short, so
the one simulation times them all.
"""

from __future__ import annotations

import numpy as np

from monitor.io.recording import Recording
from monitor.sim.cycles import RATE_LIMIT_PCT_S, rate_limit
from monitor.sim.whole.cycles import SPOOL_SIGNALS
from monitor.sim.whole.params import WholeMachine
from monitor.sim.whole.simulate import run_whole

#: How long before the rod lands (with the lever held on) the lever's return starts, as a
#: share of the return's time (the module's docstring: what each share traps).
RELEASE_EARLY = (0.1, 0.5)
#: A rod within this of its bottom stop has landed, m.
LANDED_M = 1e-4


def _spans(moving: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of every run of True."""
    edges = np.diff(np.concatenate(([0], moving.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def _cut(cmd: np.ndarray, cuts: dict[int, tuple[int, int]]) -> np.ndarray:
    """``cmd`` set to 0 over each cut's [at, stop), the lever's return rate-limited."""
    out = cmd.copy()
    for at, stop in cuts.values():
        out[at:stop] = 0.0
    return rate_limit(out, RATE_LIMIT_PCT_S)


def release_on_landing(
    commands: Recording, machine: WholeMachine, seed: int, loop: str = "boom"
) -> Recording:
    """``commands`` with every lowering of ``loop`` that lands on its bottom stop let go a
    reaction time after the simulated landing (lowerings that do not land unchanged)."""
    name = SPOOL_SIGNALS[loop]
    cmd = np.asarray(commands[name], dtype=float)
    spans = _spans(cmd < 0)
    rng = np.random.default_rng([seed, 0x1A2D])  # apart from the cycle's own draws
    return_s = np.array([-cmd[a:b].min() / RATE_LIMIT_PCT_S for a, b in spans])
    reaction = -rng.uniform(*RELEASE_EARLY, len(spans)) * return_s
    dt = float(commands.t[1] - commands.t[0])
    x = run_whole(commands, machine, ()).loop(loop, 3)
    cuts: dict[int, tuple[int, int]] = {}
    for i, (a, b) in enumerate(spans):
        down = np.flatnonzero(x[a:b] <= LANDED_M)
        if down.size:
            at = a + int(down[0]) + int(round(reaction[i] / dt))
            cuts[i] = (min(b, max(a + 1, at)), b)
    columns = {**commands.columns, name: _cut(cmd, cuts)}
    return Recording(commands.t, columns, source=commands.source, meta=commands.meta)
