"""A simulated fleet in the fleet layout, with its answer key (`monitor simulate-fleet`).

The layout is that of docs/reference/contracts.md.

Each machine's parameters are drawn within +-tolerance of the reference; each day has one oil
temperature within 35-55 degC (the oil-viscosity effect makes it matter), and the
commissioning log warms from 30 to 60 degC; one machine's piston seal and one's
spool wear slowly (severity rising linearly from the first log to the last); one machine's
flow sensor freezes (QP holds its last value) from the middle of the fleet's days on.

A day holds one log (``dayDD.log``) or several (``dayDD-L.log``, L = 1, 2, ...: a machine
that uploads after every few hours of work); file-name order is time order either way.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from monitor.sim.cycles import make_cycle
from monitor.sim.effects import parse_effect
from monitor.sim.faults import Fault
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

# Parameters drawn per machine (MachineParams parameters), each within +-tolerance.
_TOLERANCED = (
    "bulk_modulus_pa",
    "pump_disp_m3_rev",
    "valve_rated_flow_m3_s",
    "mass_kg",
    "gravity_load_n",
    "viscous_friction_n_s_m",
    "dead_volume_a_m3",
    "dead_volume_b_m3",
    "line_volume_m3",
)


@dataclass(frozen=True)
class FleetPlan:
    machines: int
    days: int
    seed: int = 0
    log_s: float = 300.0
    commissioning_s: float = 1200.0
    tolerance: float = 0.05
    wear_max: float = 0.6  # severity on the last log
    logs_per_day: int = 1


_COMMISSIONING_OIL_C = (30.0, 60.0)  # degC at the start and end of the commissioning log


def _roles(n: int) -> list[str]:
    roles = ["piston_wear", "spool_wear", "frozen_QP"]
    return [roles[i] if i < len(roles) else "healthy" for i in range(n)]


def _freeze(rec: Any, signal: str, from_s: float) -> None:
    """The sensor stops updating: every sample from ``from_s`` holds the value then."""
    col = np.array(rec.columns[signal], dtype=float)
    i = int(np.searchsorted(rec.t - rec.t[0], from_s))
    if i < len(col):
        col[i:] = col[i]
    rec.columns[signal] = col


def _write(path: Path, rec: Any) -> None:
    if path.suffix == ".csv":
        from monitor.io.csvio import write_csv

        write_csv(path, rec)
    else:
        from monitor.codec.logwrite import write_candump

        write_candump(path, rec)


def _one(
    path: Path,
    machine: Any,
    duration_s: float,
    seed: int,
    oil_c: tuple[float, float],
    faults: list[Fault],
    freeze_at_s: float | None,
) -> None:
    commands = make_cycle("boom", duration_s, seed)
    commands.columns["OilTemp"] = np.linspace(oil_c[0], oil_c[1], len(commands))
    effects = [parse_effect("oil_viscosity")]
    rec = simulate(commands, machine, faults, effects, seed=seed, rod_pos0_m=0.1)
    if freeze_at_s is not None:
        _freeze(rec, "QP", freeze_at_s)
    _write(path, rec)


def day_log_name(day: int, part: int, logs_per_day: int) -> str:
    """``day01.log`` with one log a day, else ``day01-1.log``, ``day01-2.log``, ..."""
    if logs_per_day == 1:
        return f"day{day + 1:02d}.log"
    return f"day{day + 1:02d}-{part + 1}.log"


def simulate_fleet(out: Path, plan: FleetPlan, say: Any = print) -> dict[str, Any]:
    """Write FLEET folders under ``out`` and ``out/answer_key.json``; returns the key."""
    rng = np.random.default_rng(plan.seed)
    nominal = load_machine()
    oil = [round(float(rng.uniform(35.0, 55.0)), 1) for _ in range(plan.days)]
    key: dict[str, Any] = {"plan": plan.__dict__, "oil_temp_c_per_day": oil, "machines": {}}
    for i, role in enumerate(_roles(plan.machines)):
        mid = f"M{i + 1:02d}"
        draw = {f: float(rng.uniform(1 - plan.tolerance, 1 + plan.tolerance)) for f in _TOLERANCED}
        machine = nominal.with_changes(**{f: nominal.value(f) * k for f, k in draw.items()})
        base = plan.seed * 100_000 + i * 1000
        (out / mid / "commissioning").mkdir(parents=True, exist_ok=True)
        (out / mid / "logs").mkdir(parents=True, exist_ok=True)
        # Commissioning spans the days' oil temperatures (the machine warms up from cold):
        # the model's validity range covers them, so no day is unjudged for its temperature.
        _one(
            out / mid / "commissioning" / "normal.log",
            machine,
            plan.commissioning_s,
            base,
            _COMMISSIONING_OIL_C,
            [],
            None,
        )
        days = []
        n_logs = plan.days * plan.logs_per_day
        for j in range(n_logs):
            d, part = divmod(j, plan.logs_per_day)
            sev = plan.wear_max * j / max(n_logs - 1, 1) if role.endswith("_wear") else 0.0
            faults = [Fault(role, sev)] if sev > 0 else []
            freeze = plan.log_s / 2 if role == "frozen_QP" and d >= plan.days // 2 else None
            name = day_log_name(d, part, plan.logs_per_day)
            # Seeds base + 1 + j: with one log a day, the same logs as before logs_per_day.
            _one(
                out / mid / "logs" / name,
                machine,
                plan.log_s,
                base + 1 + j,
                (oil[d], oil[d]),
                faults,
                freeze,
            )
            days.append(
                {
                    "log": f"{mid}/logs/{name}",
                    "day": d + 1,
                    "severity": round(sev, 4),
                    "sensor_frozen_from_s": freeze,
                    "oil_temp_c": oil[d],
                }
            )
        key["machines"][mid] = {"role": role, "factors": draw, "days": days}
        say(f"simulate-fleet: {mid} ({role}) written")
    (out / "answer_key.json").write_text(json.dumps(key, indent=2) + "\n", encoding="utf-8")
    return key
