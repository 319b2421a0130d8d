"""The plan of ``monitor eval-sim --machine excavator4``: which whole-machine runs, on which
seeds (light to import: no simulator, no model).

Normal runs: mixed duty cycles (truck loading, lifts with long holds) of ``NORMAL_RUN_S``
each, totalling ``normal_hours``.  Fault runs: every ``LOOP.FAULT`` x severity x onset kind x
run, the fault from ``onset_s``.  The seeds of set 0 start at ``MACHINE_SEED_BASE``, far above
every seed the shipped four models and their benchmarks were developed on (``DEV_SEEDS``),
so the default result is one nobody tuned on; ``seed_set`` K shifts them by K x 10,000,000.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from monitor.detection.alarm import AlarmConfig
from monitor.errors import ConfigError
from monitor.evaluation.plan import ONSETS, SEED_SET_STRIDE
from monitor.evaluation.sim_eval import RunSpec, check_sizes

#: The loops of the whole machine and the faults each can have (the simulator's
#: ``monitor.sim.whole.faults.LOOP_FAULTS``; the swing's spool faults are left out of the
#: default plan, its motor's leakage is the swing's own fault).
_CYLINDER_FAULTS = ("piston_wear", "spool_wear", "spool_stroke")
MACHINE_FAULTS = (
    *(f"{loop}.{f}" for loop in ("boom", "stick", "bucket") for f in _CYLINDER_FAULTS),
    "swing.motor_leakage",
    "pump.pump_wear",
)
#: Every fault the plan can take (``--faults``): the default ones and the swing's spool.
KNOWN_MACHINE_FAULTS = (*MACHINE_FAULTS, "swing.spool_wear", "swing.spool_stroke")
#: Seeds of the shipped four models' development: their training (101-106, 201-202), the
#: benchmarks of the four loops and of the hold statistic (401-412, 501-508), the tests and
#: the simulator's checks (below 1,000).  Every seed of this plan lies above them.
DEV_SEEDS = "1-999"
MACHINE_SEED_BASE = 3_000_000
NORMAL_RUN_S = 600.0
MAX_NORMAL_RUNS = 100_000  # normal seeds stay below the fault runs'
CYCLE = "mixed"


@dataclass(frozen=True)
class MachinePlan:
    """What ``monitor eval-sim --machine`` simulates, and the alarm rules it judges with."""

    severities: tuple[float, ...] = (0.3, 0.5, 1.0)
    runs: int = 10
    normal_hours: float = 100.0
    duration_s: float = 600.0  # abrupt runs; gradual runs add ramp_s
    onset_s: float = 120.0
    ramp_s: float = 60.0
    onsets: tuple[str, ...] = ("abrupt",)
    faults: tuple[str, ...] = MACHINE_FAULTS
    seed_set: int = 0
    alarm: AlarmConfig = field(default_factory=AlarmConfig)

    def __post_init__(self) -> None:
        # The section models' window is 30 s (N = 3000): J needs it filled first.
        check_sizes(self, min_onset_s=45.0, min_after_s=60.0)
        bad = [f for f in self.faults if f not in KNOWN_MACHINE_FAULTS]
        if bad or not self.faults:
            raise ConfigError(
                f"--faults {','.join(bad) or '(none)'}: the whole machine's faults are "
                f"{', '.join(KNOWN_MACHINE_FAULTS)}"
            )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["severities"] = list(self.severities)
        return d


def normal_runs(plan: MachinePlan) -> list[RunSpec]:
    """Normal pieces of ``NORMAL_RUN_S`` (the last ones shorter when the hours say so)."""
    total = plan.normal_hours * 3600.0
    if total <= 0:
        return []
    n = max(1, math.ceil(total / NORMAL_RUN_S - 1e-9))
    if n > MAX_NORMAL_RUNS:
        raise ConfigError(f"normal hours: at most {MAX_NORMAL_RUNS * NORMAL_RUN_S / 3600:g} h")
    base = MACHINE_SEED_BASE + plan.seed_set * SEED_SET_STRIDE
    return [RunSpec(base + i, round(total / n, 2), cycle=CYCLE) for i in range(n)]


def machine_fault_seed(fault: str, severity: float, onset: str, run: int) -> int:
    """Distinct per cell and run (runs < 100, severities in hundredths up to 1.0), all
    between ``MACHINE_SEED_BASE`` + 100,000 and + 500,000 (normal runs lie below)."""
    return (
        MACHINE_SEED_BASE
        + 100_000
        + 200_000 * ONSETS.index(onset)
        + 15_000 * KNOWN_MACHINE_FAULTS.index(fault)
        + 100 * int(round(severity * 100))
        + run
    )


def fault_runs(plan: MachinePlan) -> list[RunSpec]:
    out = []
    shift = plan.seed_set * SEED_SET_STRIDE
    for fault in plan.faults:
        for sev in plan.severities:
            for onset in plan.onsets:
                ramp = plan.ramp_s if onset == "gradual" else 0.0
                for r in range(plan.runs):
                    seed = machine_fault_seed(fault, sev, onset, r) + shift
                    out.append(
                        RunSpec(
                            seed,
                            plan.duration_s + ramp,
                            fault,
                            float(sev),
                            onset,
                            plan.onset_s,
                            ramp,
                            cycle=CYCLE,
                        )
                    )
    return out


def all_runs(plan: MachinePlan) -> list[RunSpec]:
    return normal_runs(plan) + fault_runs(plan)
