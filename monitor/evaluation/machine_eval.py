"""``monitor eval-sim --machine excavator4``: whole-machine runs judged loop by loop.

Each planned run (``machine_plan``) is simulated once (``monitor simulate --machine
excavator4``'s simulator and duty cycle) and every loop of the monitor config judges it as
``monitor detect --loop NAME --config config/excavator4.yaml`` does: the loop's view of the
row (``monitor.offline.recordings.split_loops``), the loop's model, the config's alarm rules
and gating (the load-sensing plausibility rules).  One row per loop and run, scored as the
boom's evaluation scores a run (``sim_eval.score_run``); a fault run's loops are then read
together (``machine_row``): was the faulty loop's alarm raised, which loop alarmed first (the
loop named) and which other loops alarmed after the onset (a neighbour's alarm).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monitor.config.settings import MonitorConfig, load_config
from monitor.detection.offline import detect
from monitor.evaluation.machine_plan import MachinePlan, all_runs
from monitor.evaluation.sim_eval import Eta, Progress, RunSpec, score_run
from monitor.io.recording import Recording
from monitor.model.machinecard import reference_reason
from monitor.model.modelfile import MonitorModel, load_model
from monitor.offline.recordings import split_loops
from monitor.sim.whole.cycles import make_whole_cycle
from monitor.sim.whole.faults import MachineFault
from monitor.sim.whole.params import WholeMachine, load_whole_machine
from monitor.sim.whole.simulate import simulate_whole

#: The fault of the pump is no loop's: any loop's alarm detects it, none names it.
PUMP = "pump"
#: Keys of a loop's row that the run's row already holds.
_RUN_KEYS = ("seed", "duration_s", "fault", "severity", "onset")


@dataclass
class MachineUnderTest:
    """The monitor config (its loops' models) judging the runs, and their rows per loop."""

    config: MonitorConfig
    models: dict[str, MonitorModel]
    normal: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    faults: list[dict[str, Any]] = field(default_factory=list)
    detect_s: float = 0.0

    @property
    def loops(self) -> list[str]:
        return list(self.models)


@functools.cache
def load_machine_monitor(config_path: str) -> MachineUnderTest:
    """The config and its loops' models, read once per process."""
    cfg = load_config(config_path)
    return MachineUnderTest(cfg, {lc.name: load_model(lc.model) for lc in cfg.monitored_loops})


@functools.cache
def _machine(sim_config: str | None) -> WholeMachine:
    return load_whole_machine(sim_config)


def simulate_machine_run(spec: RunSpec, sim_config: str | None = None) -> Recording:
    """The seeded duty cycle of the whole machine with the run's fault, every loop's DBC
    signals (``monitor simulate --machine excavator4 --cycle mixed --seed S --fault
    LOOP.FAULT:SEV@ONSET[+RAMP]`` writes the same)."""
    machine = _machine(sim_config)
    commands = make_whole_cycle(spec.cycle, spec.duration_s, spec.seed, machine)
    faults = []
    if spec.fault is not None:
        loop, _, name = spec.fault.partition(".")
        faults.append(MachineFault(name, spec.severity, spec.onset_s, spec.ramp_s, loop=loop))
    return simulate_whole(commands, machine, faults, seed=spec.seed)


def judge_loops(monitor: MachineUnderTest, rec: Recording, spec: RunSpec) -> dict[str, Any]:
    """Every loop's row of one run, as ``monitor detect --loop`` judges it."""
    cfg = monitor.config
    views = split_loops(rec, cfg, monitor.loops, rec.source)
    rows = {}
    for name, model in monitor.models.items():
        reference = reference_reason(model.card, cfg.machine_id)
        det = detect(
            model, views[name], cfg.alarm, cfg.horizon, gating=cfg.gating, reference=reference
        )
        row = score_run(det, spec)
        row["verdict"] = det.summary["verdict"]
        rows[name] = row
    return rows


def machine_row(spec: RunSpec, loops: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """A fault run's loops read together.  ``detected``: the faulty loop's alarm at or after
    the onset (the pump's: any loop's); ``named``: the loop whose alarm came first after the
    onset (``none`` if none); ``right_loop``: that loop is the faulty one; ``neighbours``:
    the other loops that alarmed after the onset (for the pump, every loop that did)."""
    assert spec.fault is not None
    faulty = spec.fault.partition(".")[0]
    alarmed = {n: r["delay_s"] for n, r in loops.items() if r["detected"]}
    first = min(alarmed, key=alarmed.__getitem__) if alarmed else "none"
    if faulty == PUMP:
        detected, delay = bool(alarmed), (alarmed[first] if alarmed else None)
    else:
        detected, delay = bool(loops[faulty]["detected"]), loops[faulty]["delay_s"]
    return {
        "seed": spec.seed,
        "fault": spec.fault,
        "loop": faulty,
        "severity": spec.severity,
        "onset": spec.onset,
        "detected": detected,
        "delay_s": delay,
        "named": first,
        "right_loop": first == faulty,
        "neighbours": sorted(n for n in alarmed if n != faulty),
        "pre_onset_alarms": {n: r["pre_onset_alarms"] for n, r in loops.items()},
        "loops": {n: {k: v for k, v in r.items() if k not in _RUN_KEYS} for n, r in loops.items()},
    }


def judge_spec(
    spec: RunSpec, config_path: str, sim_config: str | None
) -> tuple[dict[str, Any], float, float]:
    """One run simulated and judged by every loop: (row, simulation s, detection s)."""
    t0 = time.perf_counter()
    rec = simulate_machine_run(spec, sim_config)
    t1 = time.perf_counter()
    loops = judge_loops(load_machine_monitor(config_path), rec, spec)
    row = loops if spec.fault is None else machine_row(spec, loops)
    return row, t1 - t0, time.perf_counter() - t1


def judge_batch(specs: list[RunSpec], config_path: str, sim_config: str | None) -> list[Any]:
    """A Dask worker's task (``parallel.map_batches``): ``judge_spec`` of each run."""
    return [judge_spec(spec, config_path, sim_config) for spec in specs]


def file_rows(monitor: MachineUnderTest, plan: Sequence[RunSpec], scored: Sequence[Any]) -> float:
    """File every run's row with the monitor (plan order); returns the simulation seconds."""
    sim_s = 0.0
    monitor.normal = {name: [] for name in monitor.loops}
    monitor.faults = []
    for spec, (row, s, d) in zip(plan, scored, strict=True):
        sim_s += s
        monitor.detect_s += d
        if spec.fault is None:
            for name in monitor.loops:
                monitor.normal[name].append(row[name])
        else:
            monitor.faults.append(row)
    return sim_s


def judge_all(
    config_path: Path,
    plan: MachinePlan,
    workers: int = 1,
    progress: Progress | None = None,
    sim_config: str | None = None,
) -> tuple[MachineUnderTest, dict[str, float]]:
    """Every planned run simulated once and judged by every loop, in this process or on
    ``workers`` Dask processes (the same rows); returns the monitor with its rows, timings."""
    from monitor.evaluation.parallel import map_batches

    say = progress or (lambda _msg: None)
    runs = all_runs(plan)
    loaded = load_machine_monitor(str(config_path))
    monitor = MachineUnderTest(loaded.config, loaded.models)  # rows of this evaluation only
    say(
        f"judging {len(runs) - len(plan_faults(runs))} normal and {len(plan_faults(runs))} "
        f"fault run(s) of the whole machine with {len(monitor.loops)} loops' models "
        f"({', '.join(monitor.loops)}) of {config_path}"
    )
    eta = Eta(runs, say)
    if workers > 1:
        scored = map_batches(runs, judge_batch, (str(config_path), sim_config), workers, eta)
    else:
        scored = []
        for spec in runs:
            scored.append(judge_spec(spec, str(config_path), sim_config))
            eta.step(spec)
    sim_s = file_rows(monitor, runs, scored)
    return monitor, {"simulate_s": sim_s, "runs_s": time.perf_counter() - eta.started}


def plan_faults(runs: Sequence[RunSpec]) -> list[RunSpec]:
    return [r for r in runs if r.fault is not None]
