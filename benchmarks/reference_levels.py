"""Why a model of another machine withholds its alarms (docs/reference/events.md, "Judged
with a reference model"): the level the shipped model reaches on a healthy machine 15 % from
the reference, beside the reference machine itself with piston_wear 0.5 from 30 s.

Each seed: 120 s of boom duty cycle, simulated on both machines, judged with the shipped
model and config (``detect``, nothing withheld here: the levels themselves).
    python benchmarks/reference_levels.py 11 12
"""

from __future__ import annotations

import sys

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.model.modelfile import load_model
from monitor.sim.cycles import make_cycle
from monitor.sim.faults import Fault
from monitor.sim.machine import MachineParams, load_machine
from monitor.sim.simulate import simulate

AWAY = 0.15  # a larger bore, heavier boom and larger valve, a smaller pump


def away(base: MachineParams, share: float = AWAY) -> MachineParams:
    up = ("bore_m", "mass_kg", "valve_rated_flow_m3_s")
    return base.with_changes(
        **{k: base.value(k) * (1 + share) for k in up},
        pump_disp_m3_rev=base.value("pump_disp_m3_rev") * (1 - share),
    )


def main(seeds: list[int]) -> None:
    cfg = load_config()
    model = load_model(cfg.model)
    base = load_machine()
    runs = (
        ("healthy, 15 % away", away(base), []),
        ("reference, piston_wear 0.5 from 30 s", base, [Fault("piston_wear", 0.5, 30.0)]),
    )
    print("| seed | machine | max level (1 = alarm) | verdict |\n|---|---|---|---|")
    for seed in seeds:
        for name, machine, faults in runs:
            rec = simulate(make_cycle("boom", 120.0, seed), machine, faults=faults, seed=seed)
            s = detect(model, rec, cfg.alarm, cfg.horizon, gating=cfg.gating).summary
            print(f"| {seed} | {name} | {s['max_level']:.3g} | {s['verdict']} |", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [11, 12])
