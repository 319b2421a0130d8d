"""Speed and integration step of the whole-machine simulator (``--machine excavator4``).

    python benchmarks/sim_whole_check.py            # one simulated hour, then the step check

Prints the CPU and wall time of a simulated hour (duty cycle, plant, sensors) and, for a
120 s noise-free run, the largest rms / max differences of every DBC signal at 400, 200 and
100 us against a 25 us reference.
"""

from __future__ import annotations

import copy
import resource
import time

import numpy as np

from monitor.sim.whole.cycles import make_whole_cycle
from monitor.sim.whole.params import WholeMachine, load_whole_machine
from monitor.sim.whole.simulate import run_whole, sense


def speed(m: WholeMachine, seconds: float = 3600.0, seed: int = 1) -> None:
    run_whole(make_whole_cycle("mixed", 5, 0, m), m)  # compile or load numba's cache
    w0, c0 = time.perf_counter(), time.process_time()
    c = make_whole_cycle("mixed", seconds, seed, m)
    w1, c1 = time.perf_counter(), time.process_time()
    tr = run_whole(c, m)
    w2, c2 = time.perf_counter(), time.process_time()
    sense(c, tr, seed)
    w3, c3 = time.perf_counter(), time.process_time()
    print(
        f"{seconds:g} s simulated: cycle {w1 - w0:.2f} s wall / {c1 - c0:.2f} s CPU; plant "
        f"{w2 - w1:.2f} / {c2 - c1:.2f}; sensors {w3 - w2:.2f} / {c3 - c2:.2f}; total CPU "
        f"{c3 - c0:.2f} s ({seconds / (c3 - c0):.0f}x real time); peak RSS "
        f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )


def step_check(m: WholeMachine, seconds: float = 120.0, seed: int = 7) -> None:
    c = make_whole_cycle("mixed", seconds, seed, m)

    def at(step_us: float):
        values = copy.deepcopy(m.values)
        values["solver"]["step_us"] = step_us
        return sense(c, run_whole(c, WholeMachine(values, m.source)), None)

    ref = at(25)
    for step in (400, 200, 100):
        r = at(step)
        worst = sorted(
            (
                (
                    float(np.sqrt(np.mean((r[n] - ref[n]) ** 2))),
                    float(np.abs(r[n] - ref[n]).max()),
                    n,
                )
                for n in r.columns
            ),
            reverse=True,
        )[:3]
        print(f"{step} us:", ", ".join(f"{n} {a:.3f} / {b:.2f}" for a, b, n in worst))


if __name__ == "__main__":
    machine = load_whole_machine()
    speed(machine)
    step_check(machine)
