"""Step-size check of the simulator's fixed RK4 step (the table in the README).

Runs 120 s of boom duty cycle (nominal and with every effect), noise-free, at steps of
400, 200, 100 and 50 us and compares each with a 25 us reference: rms and max error of
PP, PA, PB (bar), QP (L/min) and RodPos (mm) on the 100 Hz samples.
    python benchmarks/sim_step_check.py
"""

from __future__ import annotations

import numpy as np

from monitor.sim.cycles import make_cycle
from monitor.sim.effects import CATALOGUE, Effect
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

SIGNALS = ("PP", "PA", "PB", "QP", "RodPosTrue")


def main() -> None:
    machine = load_machine()
    cmds = make_cycle("boom", 120.0, seed=1)
    print("| model | step | " + " | ".join(f"{s} rms / max" for s in SIGNALS) + " |")
    print("|---|---|" + "---|" * len(SIGNALS))
    for label, effects in (("nominal", []), ("all effects", [Effect.make(n) for n in CATALOGUE])):
        ref = simulate(cmds, machine.with_changes(step_s=25e-6), effects=effects, seed=None)
        for step_us in (400, 200, 100, 50):
            rec = simulate(
                cmds, machine.with_changes(step_s=step_us * 1e-6), effects=effects, seed=None
            )
            cells = []
            for s in SIGNALS:
                d = rec[s] - ref[s]
                cells.append(f"{np.sqrt(np.mean(d**2)):.3f} / {np.abs(d).max():.2f}")
            print(f"| {label} | {step_us} us | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
