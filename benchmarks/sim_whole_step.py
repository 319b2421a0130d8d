"""CPU per RK4 step of the whole machine's kernel (``monitor.sim.whole.kernel.integrate``).

    python benchmarks/sim_whole_step.py       # ns per step, median of 3 runs of 120 s

The plant alone (``mixed`` cycle, seed 1, 600,000 steps of 200 us), after a short call that
compiles the kernel or loads it from numba's cache; run it in each checkout, alternating,
to compare two versions.
"""

from __future__ import annotations

import statistics
import time

from monitor.sim.whole import kernel as K
from monitor.sim.whole.cycles import make_whole_cycle
from monitor.sim.whole.params import load_whole_machine
from monitor.sim.whole.simulate import pack_inputs, pack_params, rest_state


def step_ns(seconds: float = 120.0, seed: int = 1, repeats: int = 3) -> float:
    """Median CPU nanoseconds per RK4 step over ``repeats`` runs."""
    m = load_whole_machine()
    c = make_whole_cycle("mixed", seconds, seed, m)
    prm = pack_params(m)
    u = pack_inputs(c, ())
    dt = float(c.t[1] - c.t[0])
    y0 = rest_state(m, prm, u[0])
    n_sub = max(1, int(round(dt / m.step_s)))
    K.integrate(y0, u[:3], n_sub, dt, prm, n_sub)  # compile or load numba's cache
    steps = (u.shape[0] - 1) * n_sub
    runs = []
    for _ in range(repeats):
        c0 = time.process_time()
        K.integrate(y0, u, n_sub, dt, prm, n_sub)
        runs.append((time.process_time() - c0) / steps * 1e9)
    return statistics.median(runs)


if __name__ == "__main__":
    print(f"{step_ns():.0f} ns per RK4 step")
