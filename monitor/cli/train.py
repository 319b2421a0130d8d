"""``monitor train``: normal recordings (CSV or candump) -> a model file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from monitor.cli._numbers import WINDOW_MAX, number
from monitor.cli._paths import output_file
from monitor.cli._train_pump import add_pump_option, run_pump
from monitor.errors import ConfigError, MonitorError
from monitor.model.spec import PRESETS
from monitor.model.threshold import THRESHOLD_RULES, ThresholdRule
from monitor.training.settings import (
    DGRNNSettings,
    IsolationSettings,
    StatisticSettings,
    ThresholdSettings,
    TrainConfig,
)

if TYPE_CHECKING:
    from monitor.config.settings import MonitorConfig
    from monitor.io.recording import Recording
    from monitor.model.machinecard import ModelCard
    from monitor.model.modelfile import MonitorModel


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "train",
        help="train a DGRNN model on normal recordings",
        description="Fit the DGRNN on normal (fault-free) recordings, set the threshold "
        "eps0 = factor x J0 from held-out normal data, learn fault signatures from the "
        "simulator, and write a model file.",
    )
    p.add_argument(
        "recordings",
        nargs="+",
        type=Path,
        metavar="REC",
        help="normal recordings: contract CSVs or candump logs",
    )
    p.add_argument(
        "--out", type=output_file, required=True, metavar="MODEL", help="model file (.npz)"
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=None,
        help="paper: eq. 11 exactly (QP from QP, PP, PA, PB at t-1, t-2); default: "
        "PP, PA, PB, QP from their lags plus the commands and OilTemp; section: a section "
        "of a load-sensing machine, PA, PB, QP from their lags, PP and the commands, with "
        "--loop the other loops' spool commands too (default: section for --loop on a "
        "config whose plausibility.pump_system is load_sensing, else default)",
    )
    p.add_argument(
        "--rod-speed",
        action="store_true",
        help="section preset: predict the rod's speed (mm/s, from RodPos over 0.1 s) as a "
        "fourth output, so a piston leak that slows the rod for the same flow shows; the "
        "recordings need RodPos, and so does every recording the model judges",
    )
    p.add_argument(
        "--horizon",
        type=int,
        default=None,
        metavar="P",
        help="prediction horizon p in 10 ms samples (eq. 7; default: the preset's, 1)",
    )
    p.add_argument(
        "--window",
        type=number(1, WINDOW_MAX, whole=True),
        default=StatisticSettings.window_n,
        metavar="N",
        help=f"J window N in samples (eq. 9; default {StatisticSettings.window_n} = "
        f"{StatisticSettings.window_n / 100:g} s)",
    )
    p.add_argument(
        "--max-patterns",
        type=int,
        default=DGRNNSettings.max_patterns,
        metavar="K",
        help="bound on GRNN patterns (clusters of min-distance thinning; default "
        f"{DGRNNSettings.max_patterns})",
    )
    p.add_argument(
        "--threshold-rule",
        choices=THRESHOLD_RULES,
        default="max",
        help="the thresholds eps0 (of J) and b0 (of B) from their held-out normal values: "
        "max (default: factor x the largest), quantile, mean (the paper's literal reading), "
        "or evt (a Gumbel fit of the per-window maxima, for --rate false alarms per hour)",
    )
    p.add_argument("--quantile", type=float, default=0.999, help="for --threshold-rule quantile")
    p.add_argument(
        "--factor",
        type=float,
        default=2.0,
        help="eps0 = factor x J0, b0 = factor x the held-out B (default 2; not for evt)",
    )
    p.add_argument(
        "--rate",
        type=number(1e-7, 1.0),
        default=1e-3,
        metavar="PER_H",
        help="for --threshold-rule evt: false alarms per hour (default 0.001)",
    )
    p.add_argument(
        "--validation-fraction",
        type=float,
        default=0.25,
        metavar="F",
        help="share of the normal data held out for J0 (default 0.25; not used with --held-out)",
    )
    p.add_argument(
        "--held-out",
        nargs="+",
        type=Path,
        default=None,
        metavar="REC",
        help="normal recordings kept apart for the thresholds (J0 and b0) instead of a "
        "share of REC: the more normal hours here, the surer the stated false-alarm rate",
    )
    p.add_argument(
        "--reference",
        default=None,
        metavar="MODEL",
        help="a model of the same machine type trained on hours of normal data (`shipped`: "
        "the config's model): eps0 and b0 are raised to at least its thresholds, since "
        "minutes of commissioning cannot show the tail of hours (what `monitor fleet run` "
        "does with its default model); its patterns are also lent where this machine's own "
        "data has none (--lend)",
    )
    p.add_argument(
        "--stops-in-j",
        choices=("leave-out", "judge"),
        default="leave-out",
        help="leave-out: J does not judge the samples settling on an end stop (from a stall, "
        "lever out and QP below 1 L/min for 0.2 s, until the lever moves the rod again; the "
        "summary's on_stop_not_judged_s); judge: every sample, as before (default %(default)s)",
    )
    p.add_argument(
        "--support-check",
        choices=("on", "off"),
        default="on",
        help="switch off B, L or H when its held-out data does not support its threshold "
        "(fewer than 8 independent windows, one recording, or a threshold set on one half "
        "of the data that the other half exceeds); off keeps every statistic that could be "
        "fitted (default %(default)s)",
    )
    p.add_argument(
        "--folds",
        type=number(0, 20, whole=True),
        default=ThresholdSettings.folds,
        metavar="K",
        help="thresholds from residuals cross-fitted over all of REC in K folds of "
        f"{ThresholdSettings.fold_block_s:g} s blocks (needs 2K blocks, else the last "
        "--validation-fraction is held out); default 0: hold out the last "
        "--validation-fraction",
    )
    p.add_argument(
        "--lend",
        choices=("on", "off"),
        default="on",
        help="with --reference: add the reference's patterns where this machine's own data "
        "has none, so that a manoeuvre the commissioning run missed is predicted as on the "
        "reference machine instead of extrapolated (default on)",
    )
    p.add_argument(
        "--bias",
        choices=("on", "off"),
        default=None,
        help="the bias statistic B beside J (default: on, off for --preset paper); with it "
        "the full-lever statistic L (PP's mean residual with the lever beyond 80 %%), when "
        "the held-out data holds the lever there",
    )
    p.add_argument(
        "--hold",
        choices=("on", "off"),
        default="off",
        help="with B: the hold statistic H beside it (PA's and PB's mean residual in holds "
        "settled for 2 s, holds on an end stop left out), when the data runs the boom from "
        "stop to stop at least twice each way and holds the lever that long (default off: "
        "its scales are the held-out data's largest, measured on hours of it; the shipped "
        "model has H; see docs/benchmarks.md)",
    )

    p.add_argument(
        "--loop",
        default=None,
        metavar="NAME",
        help="train on this loop of whole-machine recordings (candump logs, or CSVs whose "
        "columns are the DBC's signal names; needs --config with `loops:`, whose mapping "
        "the daemon and `monitor detect --loop` read too); the fault signatures still "
        "come from the boom simulator (--isolation none leaves them out)",
    )
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="monitor YAML for --loop and for the model `--reference shipped` names",
    )
    p.add_argument(
        "--isolation",
        choices=("sim", "none"),
        default=None,
        help="learn fault signatures from the boom simulator (default) or skip (the "
        "default for a section model, whose neighbours the boom simulator has not)",
    )
    p.add_argument(
        "--isolation-runs",
        type=number(1, 100, whole=True),
        default=IsolationSettings.runs,
        metavar="N",
        help="simulated faulty runs per fault and severity for the signatures (default "
        f"{IsolationSettings.runs}; the shipped model uses 8: fewer misname slight faults)",
    )
    p.add_argument(
        "--fault-check",
        choices=("refuse", "warn", "off"),
        default="warn",
        help="run every recording through the reference model (--reference, else the "
        "config's model) first and name each one it raises an alarm on, isolated as a known "
        "fault. warn (default): name it and train on it anyway, since a healthy machine "
        "that differs from the reference's by 5-15 %% looks like a fault to it too; refuse: "
        "exit 2 before any fitting (for a reference of this very machine); off: skip",
    )
    add_pump_option(p)
    p.set_defaults(func=run)


def _card(monitor_cfg: MonitorConfig, loop_name: str | None, recordings: list) -> ModelCard:
    """The loop trained (``--loop``, or the config's first) and its configured machine
    (``monitor.offline.loopjob.loop_card``, as the fleet's commissioning writes it)."""
    from monitor.offline.loopjob import loop_card

    return loop_card(monitor_cfg, loop_name, recordings, monitor_cfg.machine_id)


def _check_input(
    args: argparse.Namespace,
    monitor_cfg: MonitorConfig,
    recordings: list[Recording],
    held_out: list[Recording],
    reference: MonitorModel | None,
) -> None:
    """The training-input checks (``monitor.training.inputcheck``), before any fitting."""
    from monitor.model.modelfile import load_model
    from monitor.training.inputcheck import (
        SuspectRecordingError,
        envelope_warnings,
        fault_suspects,
    )

    for line in envelope_warnings(recordings, monitor_cfg.gating):
        print(f"warning: {line}", file=sys.stderr)
    if args.fault_check == "off":
        return
    if reference is not None:
        name = "shipped" if args.reference == "shipped" else args.reference
    else:
        loop_model = next(
            (lc.model for lc in monitor_cfg.monitored_loops if lc.name == args.loop), None
        )
        name = str(loop_model or monitor_cfg.model)
        reference = load_model(loop_model or monitor_cfg.model)
    paths = [*args.recordings, *(args.held_out or ())]
    print(
        f"checking {len(paths)} recording(s) against the reference model {name} "
        "(--fault-check off skips)",
        file=sys.stderr,
    )
    suspects = fault_suspects(
        [*recordings, *held_out],
        paths,
        reference,
        name,
        monitor_cfg.alarm,
        monitor_cfg.horizon,
        monitor_cfg.gating,
    )
    if args.fault_check == "warn":
        for s in suspects:
            print(
                f"warning: {s.message()}, unless this machine differs from the reference "
                "model's: check the recording, leave it out if faulty (trained on it; "
                "--fault-check refuse stops here)",
                file=sys.stderr,
            )
    elif suspects:
        more = f" (and {len(suspects) - 1} more)" if len(suspects) > 1 else ""
        raise SuspectRecordingError(
            f"{suspects[0].message()}{more}. Leave it out; if it is healthy (this machine "
            "differs from the reference model's), train with --fault-check warn"
        )


def _preset(args: argparse.Namespace, monitor_cfg: MonitorConfig) -> tuple[str, tuple[str, ...]]:
    """(preset, the neighbours' demand columns it reads): ``section`` for a loop of a
    load-sensing machine unless ``--preset`` says otherwise
    (``monitor.offline.loopjob.section_inputs``, as the fleet's commissioning decides)."""
    from monitor.offline.loopjob import section_inputs

    return section_inputs(monitor_cfg, args.loop, args.preset)


def _config(args: argparse.Namespace, preset: str, neighbours: tuple[str, ...]) -> TrainConfig:
    """The training settings the options ask for (``_preset``: the model's preset)."""
    return TrainConfig(
        dgrnn=DGRNNSettings(
            preset=preset,
            horizon=args.horizon,
            max_patterns=args.max_patterns,
            lend=args.lend == "on",
            neighbours=neighbours,
            rod_speed=args.rod_speed,
        ),
        thresholds=ThresholdSettings(
            rule=ThresholdRule(args.threshold_rule, args.quantile, args.factor, args.rate),
            validation_fraction=args.validation_fraction,
            folds=args.folds,
        ),
        statistics=StatisticSettings(
            window_n=args.window,
            bias=None if args.bias is None else args.bias == "on",
            hold=args.hold == "on",
            support_check=args.support_check == "on",
            j_leaves_out_stops=args.stops_in_j == "leave-out",
        ),
        isolation=IsolationSettings(
            method=args.isolation or ("none" if neighbours else "sim"), runs=args.isolation_runs
        ),
    )


def run(args: argparse.Namespace) -> int:
    from monitor.config.settings import load_config
    from monitor.model.modelfile import load_model, save_model
    from monitor.offline.recordings import read_loop
    from monitor.training.train import train

    if args.pump:
        return run_pump(args)
    monitor_cfg = load_config(args.config)
    preset, neighbours = _preset(args, monitor_cfg)
    cfg = _config(args, preset, neighbours)
    if neighbours and cfg.isolation.method == "sim":
        raise ConfigError(
            f"--isolation sim: the boom simulator has no neighbours ({', '.join(neighbours)}) "
            "to learn a section model's fault signatures from; use --isolation none"
        )
    recordings = []
    for path in args.recordings:
        rec = read_loop(path, monitor_cfg, args.loop)
        print(f"read {path}: {len(rec)} samples ({len(rec) / 100:.0f} s)", file=sys.stderr)
        recordings.append(rec)
    held_out = []
    for path in args.held_out or ():
        rec = read_loop(path, monitor_cfg, args.loop)
        print(f"read {path} (held out): {len(rec)} samples", file=sys.stderr)
        held_out.append(rec)
    card = _card(monitor_cfg, args.loop, recordings)
    reference = None
    if args.reference is not None:
        shipped = args.reference == "shipped"
        reference = load_model(monitor_cfg.model if shipped else Path(args.reference))
    _check_input(args, monitor_cfg, recordings, held_out, reference)
    model = train(
        recordings,
        cfg,
        progress=lambda msg: print(msg, file=sys.stderr),
        held_out=held_out or None,
        reference=reference,
    )
    model.card = card
    try:
        save_model(args.out, model)
    except OSError as exc:
        raise MonitorError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    print(
        f"wrote {args.out}: preset {cfg.dgrnn.preset}, sigma {model.dgrnn.grnn.sigma_:.4g}, "
        f"N {model.window_n}, J0 {model.j0:.4g}, eps0 {model.eps0:.4g}, commissioned on "
        + (f"machine {card.machine_id!r}" if card.machine_id else "no machine (no machine_id)"),
        file=sys.stderr,
    )
    return 0
