"""The command profiles the simulator is driven with: the training cycles cover trapped
pressures at the end stops (the shipped model's training data)."""

import numpy as np

from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate


def _stop_holds(rec) -> list[tuple[float, float]]:
    """Median (PA, PB) bar of every hold longer than 0.5 s with the rod at an end stop."""
    rod = rec["RodPosTrue"]
    held = (np.abs(rec["SpoolCmd"]) < 1.0) & ((rod < 2.0) | (rod > 498.0))
    edges = np.flatnonzero(np.diff(np.r_[0, held.astype(int), 0]))
    return [
        (float(np.median(rec["PA"][a:b])), float(np.median(rec["PB"][a:b])))
        for a, b in zip(edges[::2], edges[1::2], strict=True)
        if b - a > 50
    ]


def _trapped(holds: list[tuple[float, float]]) -> int:
    # A spool that closes after the pressure built up holds the stalled levels (0 and the
    # 200 bar compensator); one that closes during the build-up traps both in between.
    return sum(15.0 < pa < 185.0 and 15.0 < pb < 185.0 for pa, pb in holds)


def test_training_cycles_close_the_spool_on_trapped_pressures_at_the_stops():
    machine = load_machine()
    boom, cover = [], []
    for seed in range(1, 5):
        for cycle, holds in (("boom", boom), ("boom-cover", cover)):
            holds += _stop_holds(simulate(make_cycle(cycle, 300.0, seed), machine, [], seed=seed))
    assert len(cover) > len(boom) > 0
    assert _trapped(boom) == 0
    assert _trapped(cover) >= 2
