"""``monitor eval-sim --machine excavator4``: whole-machine runs judged loop by loop.

Each planned run (``machine_plan``) is simulated once (``monitor simulate --machine
excavator4``'s simulator and duty cycle) and every loop of the monitor config judges it as
``monitor detect --loop NAME --config config/excavator4.yaml`` does: the loop's view of the
row (``monitor.offline.recordings.split_loops``), the loop's model, the config's alarm rules
and gating (the load-sensing plausibility rules).  One row per loop and run, scored as the
boom's evaluation scores a run (``sim_eval.score_run``); a fault run's loops are then read
together (``machine_row``): was the faulty loop's alarm raised, which loop alarmed first (the
loop named) and which other loops alarmed after the onset (a neighbour's alarm).  With a
pump model in the config (``pump:``) the pump rule judges every run too (``monitor detect
--pump``), as one more row named ``pump``, and the loop named is the machine's finding
(``monitor.detection.machine``): the pump when its rule alarmed (explaining the loops that
alarmed after its window began), else the loop whose alarm came first.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monitor.codec.frames import FrameCodec
from monitor.config.layout import row_layout
from monitor.config.pump import load_pump, pump_columns
from monitor.config.settings import MonitorConfig, load_config
from monitor.detection.machine import Alarm, finding_of
from monitor.detection.offline import detect
from monitor.detection.pump import PUMP, PumpColumns, PumpDetection, judge_rows
from monitor.evaluation.machine_plan import MachinePlan, all_runs
from monitor.evaluation.sim_eval import Eta, Progress, RunSpec, score_run
from monitor.io.recording import Recording
from monitor.model.machinecard import reference_reason
from monitor.model.modelfile import MonitorModel, load_model
from monitor.model.pumplaw import PumpModel
from monitor.offline.recordings import rows_of, split_loops
from monitor.sim.whole.cycles import make_whole_cycle
from monitor.sim.whole.faults import MachineFault
from monitor.sim.whole.params import WholeMachine, load_whole_machine
from monitor.sim.whole.simulate import simulate_whole

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
    #: The config's pump model and where its rule reads a row (None: no ``pump:``).
    pump: tuple[PumpModel, PumpColumns, tuple[str, ...]] | None = None

    @property
    def loops(self) -> list[str]:
        return list(self.models)

    @property
    def judges(self) -> list[str]:
        """The loops, and ``pump`` when the pump rule judges too."""
        return self.loops + ([PUMP] if self.pump is not None else [])


@functools.cache
def load_machine_monitor(config_path: str) -> MachineUnderTest:
    """The config and its loops' models, read once per process."""
    cfg = load_config(config_path)
    models = {lc.name: load_model(lc.model) for lc in cfg.monitored_loops}
    pump_model = load_pump(cfg)
    pump = None
    if pump_model is not None:
        columns, _ = row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
        pump = (pump_model, pump_columns(cfg, columns), columns)
    return MachineUnderTest(cfg, models, pump=pump)


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
    if monitor.pump is not None:
        pump_model, cols, columns = monitor.pump
        pump = judge_rows(pump_model, cols, rows_of(rec, columns))
        rows[PUMP] = score_pump(pump, spec, float(rec.t[-1] - rec.t[0]))
    return rows


def score_pump(det: PumpDetection, spec: RunSpec, duration_s: float) -> dict[str, Any]:
    """The pump rule's row of one run, with ``score_run``'s keys."""
    raised = [e for e in det.events if e["state"] == "fault"]
    s = det.summary
    level = None
    if s["max_margin_residual_bar"] is not None and s["threshold_bar"]:
        level = round(s["max_margin_residual_bar"] / s["threshold_bar"], 4)
    out: dict[str, Any] = {
        "seed": spec.seed,
        "duration_s": round(duration_s, 2),
        "max_level": level,
        "sensor_fault": False,
        "verdict": s["verdict"],
        "counted_s": s["counted_s"],
    }
    if spec.fault is None:
        out["alarm_episodes"] = len(raised)
        out["alarm_times_s"] = [e["t"] for e in raised]
        return out
    post = [e for e in raised if e["t"] >= spec.onset_s]
    out.update(fault=spec.fault, severity=spec.severity, onset=spec.onset)
    out["pre_onset_alarms"] = len(raised) - len(post)
    if not post:
        out.update(detected=False, delay_s=None, isolated="none")
        return out
    out.update(
        detected=True,
        delay_s=round(post[0]["t"] - spec.onset_s, 2),
        isolated="pump_wear",
        window_from_t=post[0]["window_from_t"],
    )
    return out


def machine_row(spec: RunSpec, loops: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """A fault run's loops (and the pump rule's row, ``pump``) read together.
    ``detected``: the faulty loop's alarm at or after the onset (the pump's: its rule's, or
    any loop's without a rule); ``named``: the machine's finding over the alarms after the
    onset (``monitor.detection.machine``; ``none`` if none), with its ``secondary`` and
    ``explained_by_pump`` loops; ``first_alarm``: the loop whose alarm came first;
    ``right_loop``: the finding is the faulty one; ``neighbours``: the other loops that
    alarmed after the onset (for the pump, every loop that did)."""
    assert spec.fault is not None
    faulty = spec.fault.partition(".")[0]
    alarmed = {n: r["delay_s"] for n, r in loops.items() if r["detected"] and n != PUMP}
    first = min(alarmed, key=alarmed.__getitem__) if alarmed else "none"
    finding = finding_of(_alarm(n, r, spec.onset_s) for n, r in loops.items() if r["detected"])
    named = finding.named or "none"
    if faulty == PUMP and PUMP not in loops:  # no pump rule: any loop's alarm detects it
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
        "named": named,
        "first_alarm": first,
        "right_loop": named == faulty,
        "neighbours": sorted(n for n in alarmed if n != faulty),
        "secondary": finding.secondary,
        "explained_by_pump": finding.explained,
        "pre_onset_alarms": {n: r["pre_onset_alarms"] for n, r in loops.items()},
        "loops": {n: {k: v for k, v in r.items() if k not in _RUN_KEYS} for n, r in loops.items()},
    }


def _alarm(name: str, row: dict[str, Any], onset_s: float) -> Alarm:
    """A judge's first alarm after the onset, for the machine's finding."""
    level = row["max_level"] if row["max_level"] is not None else float("nan")
    return Alarm(name, onset_s + row["delay_s"], level, row.get("window_from_t"))


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
    monitor.normal = {name: [] for name in monitor.judges}
    monitor.faults = []
    for spec, (row, s, d) in zip(plan, scored, strict=True):
        sim_s += s
        monitor.detect_s += d
        if spec.fault is None:
            for name in monitor.judges:
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
    # Rows of this evaluation only.
    monitor = MachineUnderTest(loaded.config, loaded.models, pump=loaded.pump)
    say(
        f"judging {len(runs) - len(plan_faults(runs))} normal and {len(plan_faults(runs))} "
        f"fault run(s) of the whole machine with {len(monitor.loops)} loops' models "
        f"({', '.join(monitor.loops)})"
        + (" and the pump rule" if monitor.pump is not None else "")
        + f" of {config_path}"
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
