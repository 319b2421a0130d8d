"""Machines and their recordings: what a user has, written as contract CSVs.

A machine is a drawn parameter vector with its own transducers. A recording is one run of
that machine by an operator at an oil temperature profile, read through its transducers and
written with the contract's columns (t, SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp, PP, PA,
PB, QP, RodPos); `monitor encode` turns it into a candump log.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import operator, plant, sensors
from .params import draw_machine

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
FORMATS = ("%.2f", "%.2f", "%.2f", "%.3f", "%.1f", "%.2f", "%.2f", "%.2f", "%.3f", "%.2f")


@dataclass
class Machine:
    """One machine: its plant parameters and its transducers."""

    name: str
    tolerance: float
    params: np.ndarray
    transducers: dict[str, sensors.Transducer]
    oil_sensor_offset_c: float
    speed_set_rpm: float

    @classmethod
    def draw(cls, name: str, tolerance: float, seed: int) -> Machine:
        rng = np.random.default_rng(seed)
        return cls(
            name,
            tolerance,
            draw_machine(rng, tolerance),
            sensors.draw_transducers(rng),
            float(rng.uniform(-1.0, 1.0)),
            float(2200.0 + rng.uniform(-20.0, 20.0)),
        )


@dataclass(frozen=True)
class RunSpec:
    """One recording: who operates, how long, how warm, what load, which fault."""

    duration_s: float
    style: str
    temp_start_c: float
    temp_end_c: float
    payload: float = 1.0
    fault: str = "normal"
    severity: float = 0.0
    onset_s: float = 0.0
    seed: int = 0
    meta: dict = field(default_factory=dict, compare=False)

    def temp_profile(self):
        """Warming toward temp_end like a first-order system (2 time constants in the run)."""
        t0, t1, d = self.temp_start_c, self.temp_end_c, self.duration_s

        def temp(t: np.ndarray) -> np.ndarray:
            return t0 + (t1 - t0) * (1.0 - np.exp(-2.0 * t / d)) / (1.0 - np.exp(-2.0))

        return temp


def record(machine: Machine, spec: RunSpec) -> np.ndarray:
    """The run as the contract's columns (n x 10), physical units, sensors as read."""
    rng = np.random.default_rng(spec.seed)
    tr = operator.operate(
        machine.params,
        operator.STYLES[spec.style],
        spec.duration_s,
        spec.temp_profile(),
        rng,
        spec.fault,
        spec.severity,
        spec.onset_s,
        spec.payload,
        machine.speed_set_rpm,
    )
    n = len(tr.spool)
    out = np.empty((n, len(COLUMNS)))
    out[:, 0] = np.arange(n) * plant.SAMPLE_S
    out[:, 1] = np.round(tr.spool * 100.0, 2)
    out[:, 2] = tr.disp * 100.0
    out[:, 3] = np.round(tr.speed_rpm / 0.125) * 0.125
    out[:, 4] = sensors.oil_temp_reading(
        tr.temp_c, rng, plant.SAMPLE_S, machine.oil_sensor_offset_c
    )
    truth = {
        "PP": tr.state[:, plant.PP] / 1e5,
        "PA": tr.state[:, plant.PA] / 1e5,
        "PB": tr.state[:, plant.PB] / 1e5,
        "QP": tr.state[:, plant.QS] * 60000.0,
        "RodPos": tr.state[:, plant.X] * 1000.0,
    }
    for j, name in enumerate(COLUMNS[5:], start=5):
        out[:, j] = machine.transducers[name].read(truth[name], rng)
    return out


def write_csv(path: Path, rows: np.ndarray) -> None:
    """A contract CSV."""
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, rows, fmt=list(FORMATS), delimiter=",", header=",".join(COLUMNS), comments="")
