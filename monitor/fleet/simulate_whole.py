"""A simulated fleet of whole machines (`monitor simulate-fleet --machine excavator4`).

The layout is that of docs/reference/contracts.md, each log a whole-machine recording: every
loop's signals of dbc/excavator4.dbc (boom, stick, bucket, swing on one load-sensing pump),
as `monitor simulate --machine excavator4` writes them.

Each machine's parameters (config/excavator4_sim.yaml) are drawn within +-tolerance of the
nominal ones (:data:`TOLERANCED`).  Its commissioning log is the ``mixed`` duty cycle with
the oil warming from 30 to 60 degC; each daily log runs one duty cycle drawn from
``mixed``, ``truck-loading`` and ``lifting`` (seeded) at the day's oil temperature
(35-55 degC).  The first machines carry a fault in one loop (:data:`ROLES`: the stick's
piston seal, the bucket's spool, the swing motor, the shared pump), its severity rising
linearly from 0 in the first log to ``wear_max`` in the last; the others are healthy.
``answer_key.json`` says which is which, log by log.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from monitor.fleet.simulate import FleetPlan, day_log_name
from monitor.resources import resource_path
from monitor.sim.whole.cycles import WHOLE_CYCLES, make_whole_cycle
from monitor.sim.whole.faults import MachineFault
from monitor.sim.whole.params import WholeMachine, load_whole_machine, machine_from_mapping
from monitor.sim.whole.simulate import simulate_whole

MACHINE = "excavator4"
#: Values drawn per machine within +-tolerance, as ``section.key`` of the whole machine's
#: YAML: what differs from one machine of a series to the next (masses, valve gains, pump
#: displacement, volumes, friction, leakage), never the geometry.
TOLERANCED = (
    "oil.bulk_modulus_gpa",
    "pump.displacement_cc_rev",
    "pump.line_volume_l",
    "valve.boom_rated_flow_lpm",
    "valve.stick_rated_flow_lpm",
    "valve.bucket_rated_flow_lpm",
    "valve.swing_rated_flow_lpm",
    *(f"{c}.{k}" for c in ("boom", "stick", "bucket") for k in ("mass_kg", "dead_volume_l")),
    *(f"{c}.viscous_friction_n_s_per_m" for c in ("boom", "stick", "bucket")),
    "swing.house_mass_kg",
    "swing.line_volume_l",
    "swing.motor_leakage_cc_min_per_bar",
    "swing.viscous_friction_n_m_s",
)
#: (loop, fault) of the first machines, M01, M02, ...; the machines after them are healthy.
ROLES: tuple[tuple[str, str], ...] = (
    ("stick", "piston_wear"),
    ("bucket", "spool_wear"),
    ("swing", "motor_leakage"),
    ("pump", "pump_wear"),
)
COMMISSIONING_CYCLE = "mixed"
_COMMISSIONING_OIL_C = (30.0, 60.0)  # degC at the start and end of the commissioning log


def role(i: int, roles: tuple[tuple[str, str], ...] = ROLES) -> str:
    """Machine ``i``'s (from 0) role: ``LOOP.FAULT`` of ``roles``, or ``healthy``."""
    return ".".join(roles[i]) if i < len(roles) and roles[i][1] else "healthy"


def toleranced(nominal: WholeMachine, factors: dict[str, float], label: str) -> WholeMachine:
    """``nominal`` with each ``section.key`` of ``factors`` multiplied by its factor,
    validated as the YAML is."""
    values = {section: dict(keys) for section, keys in nominal.values.items()}
    for name, k in factors.items():
        section, key = name.split(".")
        values[section][key] *= k
    return machine_from_mapping(values, f"{nominal.source} ({label})")


def _write(path: Path, rec: Any) -> None:
    if path.suffix == ".csv":
        from monitor.io.csvio import write_csv

        write_csv(path, rec)
    else:
        from monitor.codec.frames import FrameCodec
        from monitor.codec.logwrite import write_candump

        write_candump(path, rec, codec=FrameCodec.from_dbc(resource_path("dbc", "excavator4.dbc")))


def _one(
    path: Path,
    machine: WholeMachine,
    cycle: str,
    duration_s: float,
    seed: int,
    oil_c: tuple[float, float],
    faults: list[MachineFault],
) -> None:
    commands = make_whole_cycle(cycle, duration_s, seed, machine)
    commands.columns["OilTemp"] = np.linspace(oil_c[0], oil_c[1], len(commands))
    _write(path, simulate_whole(commands, machine, faults, seed=seed))


def _days(
    out: Path,
    i: int,
    machine: WholeMachine,
    plan: FleetPlan,
    cycles: list[str],
    oil: list[float],
    roles: tuple[tuple[str, str], ...] = ROLES,
) -> list[dict[str, Any]]:
    """Machine ``i``'s (from 0) daily logs written; one answer-key entry per log."""
    mid = f"M{i + 1:02d}"
    loop, _, fault = role(i, roles).partition(".")
    base = plan.seed * 100_000 + i * 1000
    n_logs = plan.days * plan.logs_per_day
    days = []
    for j in range(n_logs):
        d, part = divmod(j, plan.logs_per_day)
        sev = plan.wear_max * j / max(n_logs - 1, 1) if fault else 0.0
        faults = [MachineFault(fault, sev, loop=loop)] if sev > 0 else []
        name = day_log_name(d, part, plan.logs_per_day)
        cycle = cycles[j]
        path = out / mid / "logs" / name
        _one(path, machine, cycle, plan.log_s, base + 1 + j, (oil[d], oil[d]), faults)
        days.append(
            {
                "log": f"{mid}/logs/{name}",
                "day": d + 1,
                "cycle": cycle,
                "seed": base + 1 + j,
                "fault": f"{loop}.{fault}" if sev > 0 else None,
                "severity": round(sev, 4),
                "oil_temp_c": oil[d],
            }
        )
    return days


def simulate_whole_fleet(
    out: Path,
    plan: FleetPlan,
    say: Any = print,
    machine: WholeMachine | None = None,
    roles: tuple[tuple[str, str], ...] = ROLES,
) -> dict[str, Any]:
    """Write FLEET folders of whole machines under ``out`` and ``out/answer_key.json``;
    returns the key (``machine``: the nominal whole machine, default the shipped one;
    ``roles``: the first machines' (loop, fault), :data:`ROLES` by default, ``("", "")``
    for a healthy one).
    ``plan`` is the single-boom fleet's: machines x days x logs_per_day logs of log_s
    seconds, a commissioning log of commissioning_s, +-tolerance, wear_max."""
    rng = np.random.default_rng(plan.seed)
    nominal = machine or load_whole_machine()
    oil = [round(float(rng.uniform(35.0, 55.0)), 1) for _ in range(plan.days)]
    key: dict[str, Any] = {
        "machine": MACHINE,
        "plan": asdict(plan),
        "oil_temp_c_per_day": oil,
        "machines": {},
    }
    for i in range(plan.machines):
        mid = f"M{i + 1:02d}"
        draw = {f: float(rng.uniform(1 - plan.tolerance, 1 + plan.tolerance)) for f in TOLERANCED}
        machine_i = toleranced(nominal, draw, mid)
        base = plan.seed * 100_000 + i * 1000
        (out / mid / "commissioning").mkdir(parents=True, exist_ok=True)
        (out / mid / "logs").mkdir(parents=True, exist_ok=True)
        # Commissioning spans the days' oil temperatures (the machine warms up from cold).
        _one(
            out / mid / "commissioning" / "normal.log",
            machine_i,
            COMMISSIONING_CYCLE,
            plan.commissioning_s,
            base,
            _COMMISSIONING_OIL_C,
            [],
        )
        n_logs = plan.days * plan.logs_per_day
        cycles = [WHOLE_CYCLES[int(c)] for c in rng.integers(0, len(WHOLE_CYCLES), n_logs)]
        days = _days(out, i, machine_i, plan, cycles, oil, roles)
        key["machines"][mid] = {
            "role": role(i, roles),
            "factors": draw,
            "commissioning": {"cycle": COMMISSIONING_CYCLE, "seed": base},
            "days": days,
        }
        say(f"simulate-fleet: {mid} ({role(i, roles)}) written")
    (out / "answer_key.json").write_text(json.dumps(key, indent=2) + "\n", encoding="utf-8")
    return key
