"""``monitor eval-sim --machine excavator4``: the whole machine's loops on simulated runs."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from monitor.cli._eval_sim_args import plan_flags, write_result
from monitor.errors import ConfigError

if TYPE_CHECKING:
    from monitor.evaluation.machine_plan import MachinePlan

MACHINES = ("excavator4",)
#: Options of the boom loop's evaluation (training presets, twin runs) the machine's has not.
_BOOM_ONLY = (
    ("model", "--model"),
    ("presets", "--presets"),
    ("train_seeds", "--train-seeds"),
    ("train_duration", "--train-duration"),
    ("isolation_runs", "--isolation-runs"),
    ("twins", "--no-twins"),
    ("twin_residuals", "--twin-residuals"),
    ("horizon", "--horizon"),
)
#: The sizes of ``--quick`` and of the full evaluation, where the option is not given:
#: severities, runs per cell, normal hours, fault run length (s).
_QUICK: dict[str, Any] = {
    "severities": (0.5,),
    "runs": 1,
    "normal_hours": 1 / 6,
    "duration": 300.0,
}
_FULL: dict[str, Any] = {
    "severities": (0.3, 0.5, 1.0),
    "runs": 10,
    "normal_hours": 100.0,  # the measure: 0 false alarms in at least 100 h per loop
    "duration": 600.0,
}


def add_machine_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--machine",
        choices=MACHINES,
        default=None,
        help="evaluate the whole machine instead (excavator4: the loops of --config, default "
        "config/excavator4.yaml, with their shipped models, on simulated mixed duty cycles; "
        "per loop false alarms, per LOOP.FAULT detection, delay and the loop named)",
    )


def _given(value: Any, default: Any) -> Any:
    return default if value is None else value


def machine_plan(args: argparse.Namespace, alarm: Any) -> MachinePlan:
    """The plan of the options given, else the machine's (or --quick's) sizes."""
    from monitor.evaluation.machine_plan import MACHINE_FAULTS, MachinePlan

    base = _QUICK if args.quick else _FULL
    return MachinePlan(
        severities=tuple(round(s, 6) for s in _given(args.severities, base["severities"])),
        runs=_given(args.runs, base["runs"]),
        normal_hours=_given(args.normal_hours, base["normal_hours"]),
        duration_s=_given(args.duration, base["duration"]),
        onset_s=_given(args.onset, 120.0),
        ramp_s=_given(args.ramp, 60.0),
        onsets=_given(args.onsets, ("abrupt",)),
        faults=_given(args.faults, MACHINE_FAULTS),
        seed_set=args.seed_set,
        alarm=alarm,
    )


def _given_option(args: argparse.Namespace, key: str) -> bool:
    """Whether the option was given: not None (``--no-twins`` given is False), except
    ``--twin-residuals``, a switch that is False when not given."""
    value = getattr(args, key, None)
    return bool(value) if key == "twin_residuals" else value is not None


def rerun_command(args: argparse.Namespace, plan: MachinePlan) -> str:
    """The explicit command that reproduces this evaluation (no --quick shorthand)."""
    from monitor.evaluation.machine_plan import MACHINE_FAULTS

    parts = [f"monitor eval-sim --machine {args.machine}", *plan_flags(plan, MACHINE_FAULTS)]
    if args.config:
        parts.append(f"--config {args.config}")
    if plan.seed_set:
        parts.append(f"--seed-set {plan.seed_set}")
    return " ".join(parts) + " --json F"


def run_machine(args: argparse.Namespace, say: Callable[[str], None]) -> int:
    """Check the options, judge every run, write the JSON and the report."""
    from monitor.config.settings import load_config
    from monitor.evaluation.machine_eval import judge_all
    from monitor.evaluation.machine_report import machine_markdown, machine_record
    from monitor.resources import resource_path

    started = time.perf_counter()
    given = [flag for key, flag in _BOOM_ONLY if _given_option(args, key)]
    if given:
        raise ConfigError(
            f"{', '.join(given)}: not with --machine (the whole machine is judged by the "
            "models its --config names, each loop's own)"
        )
    config_path = Path(args.config or resource_path("config", "excavator4.yaml"))
    conf = load_config(config_path)
    if len(conf.monitored_loops) < 2:
        raise ConfigError(f"{config_path}: --machine needs a config with the machine's loops")
    plan = machine_plan(args, conf.alarm)
    loops = [lc.name for lc in conf.monitored_loops]
    missing = sorted({f.partition(".")[0] for f in plan.faults} - {*loops, "pump"})
    if missing:
        raise ConfigError(
            f"{config_path}: no loop {', '.join(missing)} to judge its faults; loops: "
            f"{', '.join(loops)}"
        )
    for path in (args.json, args.markdown):
        if path is not None and not path.parent.is_dir():
            raise ConfigError(f"{path}: folder {path.parent} does not exist")
    monitor, timing = judge_all(config_path, plan, args.workers, say)
    result = machine_record(
        rerun_command(args, plan),
        str(config_path),
        plan,
        monitor,
        args.workers,
        {**timing, "total": time.perf_counter() - started},
    )
    write_result(args, result, machine_markdown(result))
    say(f"done in {time.perf_counter() - started:.0f} s -> {args.json}")
    return 0
