"""``monitor eval-sim``: the simulated evaluation of issue 3, as one rerunnable command."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from monitor.cli._eval_sim_args import (
    boom_defaults,
    fault_names,
    floats,
    names,
    plan_flags,
    seeds,
    write_result,
)
from monitor.cli._eval_sim_machine import add_machine_option, run_machine
from monitor.cli._numbers import number
from monitor.cli._paths import output_file
from monitor.errors import ConfigError
from monitor.evaluation.plan import DEFAULT_SEVERITIES, ISOLATION_RUNS, MAX_SEED_SET, ONSETS
from monitor.model.spec import PRESETS
from monitor.signals import FAULT_NAMES

if TYPE_CHECKING:
    from monitor.config.settings import MonitorConfig
    from monitor.evaluation.sim_eval import EvalConfig, ModelUnderTest

T = TypeVar("T")

_DESCRIPTION = """\
Train DGRNN models afresh on normal simulated operation (--presets, default
default,paper; seeds --train-seeds, 300 s each: patterns from boom-cover cycles of the first
half, the thresholds from boom cycles of the second half held out, as
config/train_default_model.sh does with seeds 1-240) and/or
load model files (--model; 'shipped' = the model config/monitor.yaml names), then score
simulated runs of other seeds: normal runs totalling --normal-hours (false alarms = entries
into the fault state, per hour), and every fault x severity x onset (abrupt at --onset;
gradual over --ramp s) x --runs.  Detected = an alarm at or after the onset; delay = alarm
time - onset; isolation = the fault the alarm names.  Alarms before the onset are false
alarms, reported separately.  Writes --json and a markdown report (stdout or --markdown).

Twin runs: every fault run is also simulated noise-free with and without the fault; the
J of the difference (the model's z-units and window) over eps0 is the run's fault_j_ratio,
and a run whose ratio reached 1 counts as exercised (the report splits detection by it).
They add one plant run per fault run (~0.16 s per 120 s run); --no-twins skips them.
--twin-residuals also runs each model on both twins: the alarm level the fault alone gives
this detector's residual (fault_residual_level_ratio; "passed" in the report).

Cost: a 300 s normal run simulates in ~1.4 s and is scored in ~0.5 s per model (default
preset, 6000 patterns, p=1).  The full default evaluation (600 fault runs, 100 h normal, two
presets) takes about an hour with --workers 2 on a 2-core machine; --quick about a minute.

The whole machine (--machine excavator4): nothing is trained; the loops of --config
(default config/excavator4.yaml) with their models judge simulated mixed duty cycles as
`monitor detect --loop` does.  Per loop: false alarms per hour on --normal-hours (default
100) of normal work.  Per LOOP.FAULT (default: piston_wear, spool_wear and spool_stroke of
boom, stick and bucket, swing.motor_leakage, pump.pump_wear) x severity (default 0.3,0.5,1)
x --runs (default 10), 600 s runs with the onset at 120 s: detected = the faulty loop's
alarm (the pump's: any loop's), delay, the loop named (the first to alarm) and the runs in
which a neighbour's alarm was raised.  Seed set 0 lies above every seed the shipped models
were developed on (1-999).  --quick: one run per fault at 0.5 and 10 normal minutes.
"""


@dataclass(frozen=True)
class _Scale:
    """The defaults of an evaluation's size (each option given on the command line wins)."""

    severities: tuple[float, ...]
    runs: int
    normal_hours: float
    train_seeds: tuple[int, ...]
    presets: tuple[str, ...]


def _given(value: T | None, default: T) -> T:
    """The command line's ``value``, or ``default`` where the option was not given."""
    return default if value is None else value


#: The reduced set CI affords (about a minute): the default preset trained as the shipped
#: model is, 2 severities x 2 onsets x 2 runs per fault, 10 normal minutes.
QUICK = _Scale(
    severities=(0.5, 1.0),
    runs=2,
    normal_hours=1 / 6,
    train_seeds=tuple(range(1, 9)),
    presets=("default",),
)
FULL = _Scale(
    severities=DEFAULT_SEVERITIES,
    runs=10,
    normal_hours=100.0,  # a false-alarm rate below 0.03/h can only be shown on 100 h
    train_seeds=tuple(range(1, 49)),
    presets=("default", "paper"),
)


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "eval-sim",
        help="simulated evaluation: detection, delay, isolation and false alarms on many runs",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--json", metavar="F", type=output_file, required=True, help="results to write")
    p.add_argument("--markdown", metavar="F.md", type=output_file, help="tables (default: stdout)")
    p.add_argument(
        "--model",
        metavar="MODEL",
        action="append",
        default=None,
        help="evaluate this model file (repeatable; 'shipped' = config's model); without "
        "--presets, nothing is trained",
    )
    p.add_argument(
        "--presets",
        metavar="LIST",
        type=names(tuple(PRESETS)),
        default=None,
        help="presets to train afresh (default default,paper; --quick default; none with --model)",
    )
    p.add_argument(
        "--train-seeds",
        metavar="SEEDS",
        type=seeds,
        default=None,
        help="seeds of the normal training runs (default 1-48; --quick 1-8)",
    )
    p.add_argument(
        "--train-duration",
        metavar="S",
        type=float,
        default=None,
        help="length of each training run (default 300 s)",
    )
    p.add_argument(
        "--isolation-runs",
        type=number(1, 100, whole=True),
        default=None,
        metavar="N",
        help="simulated faulty runs per fault and severity from which each trained preset "
        f"learns its fault signatures (default {ISOLATION_RUNS}, as the shipped model; fewer "
        "train faster and misname slight faults more often)",
    )
    p.add_argument(
        "--runs",
        metavar="K",
        type=int,
        default=None,
        help="runs per fault, severity and onset (default 10; --quick 2)",
    )
    p.add_argument(
        "--severities",
        metavar="LIST",
        type=floats,
        default=None,
        help="fault severities (default 0.1,0.2,...,1.0; --quick 0.5,1.0)",
    )
    p.add_argument(
        "--faults",
        metavar="LIST",
        type=fault_names,
        default=None,
        help=f"faults to simulate (default all: {','.join(FAULT_NAMES)}; with --machine "
        "LOOP.FAULT names)",
    )
    p.add_argument(
        "--onsets",
        metavar="LIST",
        type=names(ONSETS),
        default=None,
        help="abrupt,gradual (default both; with --machine abrupt)",
    )
    p.add_argument(
        "--normal-hours",
        metavar="H",
        type=float,
        default=None,
        help="hours of normal test runs (default 100; --quick 1/6)",
    )
    p.add_argument(
        "--duration",
        metavar="S",
        type=float,
        default=None,
        help="abrupt fault run length (default 120 s, with --machine 600 s; gradual: + ramp)",
    )
    p.add_argument(
        "--onset",
        metavar="S",
        type=float,
        default=None,
        help="fault onset (default 30 s, with --machine 120 s)",
    )
    p.add_argument(
        "--ramp",
        metavar="S",
        type=float,
        default=None,
        help="ramp of a gradual fault (default 30 s, with --machine 60 s)",
    )
    p.add_argument(
        "--horizon",
        metavar="P",
        type=int,
        default=None,
        help="prediction horizon p (default: config's, 1)",
    )
    p.add_argument(
        "--config",
        metavar="FILE",
        type=Path,
        default=None,
        help="monitor config for the alarm debounce and shipped model",
    )
    p.add_argument(
        "--workers",
        type=number(1, 256, whole=True),
        default=1,
        metavar="N",
        help="Dask worker processes on this machine (LocalCluster; default 1: one "
        "process, no Dask); the rows are the same either way",
    )
    p.add_argument(
        "--seed-set",
        type=number(0, MAX_SEED_SET, whole=True),
        default=0,
        metavar="K",
        help="test seeds shifted by K x 10,000,000: 0 (default) are "
        "the development seeds; report a blind result on a set nobody tuned on",
    )
    p.add_argument(
        "--no-twins",
        dest="twins",
        action="store_false",
        default=None,
        help="skip the noise-free twins of each fault run (with and without the "
        "fault) that give fault_j_ratio and the 'exercised' columns",
    )
    p.add_argument(
        "--twin-residuals",
        action="store_true",
        help="also run each model on both twins: fault_residual_level_ratio, the "
        "alarm level the fault alone gives this detector (two more predictions per "
        "fault run and model)",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="the reduced set CI runs (~1 min); explicit options win",
    )
    add_machine_option(p)
    p.set_defaults(func=run)


def _say(msg: str) -> None:
    print(f"eval-sim: {msg}", file=sys.stderr, flush=True)


def _rerun(
    args: argparse.Namespace, cfg: EvalConfig, presets: tuple[str, ...], seeds: tuple[int, ...]
) -> str:
    """The explicit command that reproduces this evaluation (no --quick shorthand)."""
    parts = ["monitor eval-sim"]
    parts += [f"--model {m}" for m in args.model or ()]
    if presets:
        parts += [f"--presets {','.join(presets)}", f"--train-seeds {','.join(map(str, seeds))}"]
        parts.append(f"--train-duration {args.train_duration:g}")
        if args.isolation_runs != ISOLATION_RUNS:
            parts.append(f"--isolation-runs {args.isolation_runs}")
    parts += plan_flags(cfg, FAULT_NAMES)
    if args.horizon:
        parts.append(f"--horizon {args.horizon}")
    if args.config:
        parts.append(f"--config {args.config}")
    if cfg.seed_set:
        parts.append(f"--seed-set {cfg.seed_set}")
    if not cfg.twins:
        parts.append("--no-twins")
    if cfg.twin_residuals:
        parts.append("--twin-residuals")
    return " ".join(parts) + " --json F"


def run(args: argparse.Namespace) -> int:
    from monitor.config.settings import load_config
    from monitor.evaluation.parallel import score_all
    from monitor.evaluation.report import Training, evaluation_record, markdown

    if args.machine is not None:
        return run_machine(args, _say)
    boom_defaults(args)
    started = time.perf_counter()
    base = QUICK if args.quick else FULL
    conf = load_config(args.config)
    cfg = _eval_config(args, base, conf)
    presets, train_seeds = _training(args, base, cfg)
    for path in (args.json, args.markdown):
        if path is not None and not path.parent.is_dir():
            raise ConfigError(f"{path}: folder {path.parent} does not exist")
    models = _models(args, conf, presets, train_seeds)
    timing = score_all(models, cfg, args.workers, _say)
    total = time.perf_counter() - started
    result = evaluation_record(
        _rerun(args, cfg, presets, train_seeds),
        cfg,
        models,
        Training(train_seeds, args.train_duration, args.isolation_runs) if presets else None,
        args.workers,
        {**timing, "total": total},
    )
    write_result(args, result, markdown(result))
    _say(f"done in {total:.0f} s -> {args.json}")
    return 0


def _eval_config(args: argparse.Namespace, base: _Scale, conf: MonitorConfig) -> EvalConfig:
    """What to simulate and how to judge it: the options given, else ``base``'s sizes."""
    from monitor.evaluation.sim_eval import EvalConfig

    return EvalConfig(
        severities=tuple(round(s, 6) for s in _given(args.severities, base.severities)),
        runs=_given(args.runs, base.runs),
        normal_hours=_given(args.normal_hours, base.normal_hours),
        duration_s=_given(args.duration, 120.0),
        onset_s=_given(args.onset, 30.0),
        ramp_s=_given(args.ramp, 30.0),
        onsets=_given(args.onsets, ONSETS),
        faults=_given(args.faults, FAULT_NAMES),
        horizon=args.horizon or conf.horizon,
        alarm=conf.alarm,
        seed_set=args.seed_set,
        twins=args.twins is not False,
        twin_residuals=args.twin_residuals,
    )


def _training(
    args: argparse.Namespace, base: _Scale, cfg: EvalConfig
) -> tuple[tuple[str, ...], tuple[int, ...]]:
    """The presets to train afresh and their seeds, checked against the test seeds."""
    from monitor.evaluation.sim_eval import planned_seeds

    presets = args.presets
    if presets is None:
        presets = () if args.model else base.presets
    train_seeds = _given(args.train_seeds, base.train_seeds)
    overlap = sorted(set(train_seeds) & planned_seeds(cfg)) if presets else []
    if overlap:
        raise ConfigError(f"--train-seeds overlap the test seeds: {overlap[:5]}")
    if not args.train_duration >= 60:
        raise ConfigError("--train-duration must be at least 60 s")
    return presets, train_seeds


def _models(
    args: argparse.Namespace,
    conf: MonitorConfig,
    presets: tuple[str, ...],
    train_seeds: tuple[int, ...],
) -> list[ModelUnderTest]:
    """The model files given (--model), then the presets trained afresh."""
    from monitor.evaluation.sim_eval import ModelUnderTest, train_presets
    from monitor.model.modelfile import load_model

    models: list[ModelUnderTest] = []
    for name in args.model or ():
        path = conf.model if name == "shipped" else Path(name)
        label = "shipped" if name == "shipped" else path.stem
        models.append(ModelUnderTest(label, load_model(path), f"model file {path}"))
    models += train_presets(presets, train_seeds, args.train_duration, _say, args.isolation_runs)
    return models
