"""One recording: a machine, an effect (or none), a duty cycle, simulated and read."""

from __future__ import annotations

import csv
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.gap_third import cycles, machine, plant, sensors

DT_S = 1e-4  # RK4 step; the stiffest mode (valve edge near closed, 0.3 L) is ~1e4 1/s
COLUMNS = (
    "t",
    "SpoolCmd",
    "PumpDispCmd",
    "EngineSpeed",
    "OilTemp",
    "PP",
    "PA",
    "PB",
    "QP",
    "RodPos",
)


@dataclass
class Scenario:
    """What a recording is (the answer key entry)."""

    name: str
    seed: int
    effect: str  # a catalogue name, "none", or an out-of-catalogue name
    tolerance: float  # 0.03 or 0.12
    rodpos: bool
    warmup: bool
    duration_s: float = 300.0
    expected: str = ""  # the verdict a right diagnosis gives
    mechanism: str | None = None  # out of catalogue: the suggestion kind expected first
    signal: str | None = None  # sensor_calibration: the signal
    params: dict = field(default_factory=dict)
    factors: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        d = asdict(self)
        d["params"] = {
            k: (round(v, 6) if isinstance(v, float) else v) for k, v in self.params.items()
        }
        return d


def build(sc: Scenario) -> tuple[np.ndarray, dict, dict]:
    """Draw the machine and effect (fills the key); parameter vector, inputs, sensors."""
    rng = np.random.default_rng(sc.seed)
    prm = machine.nominal()
    sc.factors = machine.draw_machine(prm, sc.tolerance, rng)
    sens: dict = {}
    if sc.effect != "none":
        sc.params, sens = machine.apply_effect(sc.effect, prm, rng, sc.rodpos)
    sc.expected = (
        sc.effect if sc.effect in machine.CATALOGUE or sc.effect == "none" else "unexplained"
    )
    sc.mechanism = machine.OUT_OF_CATALOGUE.get(sc.effect)
    sc.signal = sens.get("signal") if sc.effect == "sensor_calibration" else None
    inputs = cycles.boom_cycles(sc.duration_s, rng, sc.warmup)
    return prm, inputs, sens


def initial_state(prm: np.ndarray) -> np.ndarray:
    """Rod at rest on the bottom stop, the load on the cap side, engine at speed."""
    s = np.zeros(plant.N_STATES)
    s[1] = plant.load_force(prm, 0.0) / prm[plant.AREA_A]
    s[10] = 2200.0
    return s


def simulate(prm: np.ndarray, inputs: dict) -> np.ndarray:
    """The plant's 1 kHz states for these inputs."""
    return plant.run(
        prm,
        initial_state(prm),
        inputs["spool"],
        inputs["disp"],
        inputs["n_set"],
        inputs["temp"],
        inputs["ripple"],
        DT_S,
    )


def record(sc: Scenario, path: Path) -> dict:
    """Simulate the scenario, write its contract CSV; returns the key entry."""
    prm, inputs, sens = build(sc)
    states = simulate(prm, inputs)
    if not np.all(np.isfinite(states)):
        raise RuntimeError(f"{sc.name}: the plant diverged")
    cols = sensors.read(
        states, inputs, sens, sc.effect, sc.rodpos, np.random.default_rng(sc.seed + 7_000_003)
    )
    names = [c for c in COLUMNS if c in cols]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        fmt = {"t": "{:.4f}", "EngineSpeed": "{:.3f}"}
        for row in zip(*(cols[c] for c in names), strict=True):
            w.writerow([fmt.get(c, "{:.2f}").format(v) for c, v in zip(names, row, strict=True)])
    return sc.to_json()
