"""Simulator speed (pytest-benchmark; run with ``python -m pytest benchmarks --benchmark-enable``).

Issue goal: a 10-minute trace at 100 Hz with every effect on in under 5 s, a 150 s segment
in under 1 s, on a 2-core machine.  Each case times cycle generation, integration and the
sensor model, i.e. what ``monitor simulate`` does before writing the file.
"""

from __future__ import annotations

import pytest

from monitor.sim.cycles import make_cycle
from monitor.sim.effects import CATALOGUE, Effect
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

MACHINE = load_machine()
ALL_EFFECTS = [Effect.make(name) for name in CATALOGUE]


def _run(duration_s: float, effects: list[Effect]) -> None:
    simulate(make_cycle("boom", duration_s, seed=1), MACHINE, effects=effects, seed=1)


@pytest.mark.parametrize(
    "duration_s, effects",
    [(600.0, ALL_EFFECTS), (150.0, ALL_EFFECTS), (600.0, [])],
    ids=["600s-all-effects", "150s-all-effects", "600s-nominal"],
)
def test_simulate_speed(benchmark, duration_s, effects):
    _run(2.0, effects)  # compile (or load the numba cache) outside the timing
    benchmark.pedantic(_run, args=(duration_s, effects), rounds=3, iterations=1)
