"""``monitor gap``: where the simulator departs from a recording and which effect it misses."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from monitor.cli._paths import output_dir, output_file
from monitor.errors import ConfigError, MonitorError
from monitor.io.recording import Recording
from monitor.sampling.read import read_recording
from monitor.sim.machine import MachineParams, load_machine

_EPILOG = """\
how it works:
  The simulator is driven by the recording's own commands (SpoolCmd, PumpDispCmd,
  EngineSpeed, OilTemp) segment by segment, each segment started from the measured state
  (RodPos when present, otherwise rod position integrated from QP and re-anchored at the
  end stops).  Tolerances (mass, gravity load, friction, valve gain, volumes) are
  calibrated first; then every effect of the catalogue is fitted on a calibration part and
  scored on a held-out part.

verdict: an effect name, `none` (gap within sensor noise) or `unexplained` (no effect
removes a clear share of the held-out gap).  JSON keys: verdict, also, params, calibrated,
confidence, where{signals,regimes,bands,windows}, ranking, shrink{before,after,
heldout_reduction}; for `unexplained` also suggestion (what to model next: one or two
terms with term, signal, description, coefficient, unit, heldout_reduction).
A `sensor_calibration` verdict (gain and offset of one measured signal) has
params.sensor_calibration keyed by the signal: PA_gain, PA_offset_bar, QP_offset_lpm,
RodPos_offset_mm, ...  lag_check: how QP and PP follow the engine's speed ripple
(prompt: not a sensor lag; late: a sensor lag), when sensor_lag was in question.

exit status: 0 diagnosed (whatever the verdict), 2 bad argument/config/file or commands
missing (a whole-machine recording without --loop, a loop the config does not have), 3 a
recording the tool cannot use (too short, no hydraulic signals, no motion, another
machine's signals) or a loop the single-loop simulator cannot stand for (--loop swing, a
loop sharing a load-sensing pump: every loop of config/excavator4.yaml).

example:
  monitor simulate --duration 300 --seed 1 --effect valve_deadband:overlap_pct=12 --out r.csv
  monitor gap --real r.csv --json gap.json --report gap/
  monitor gap --real whole.log --loop stick --loops-config my-machine.yaml --json stick.json
"""


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "gap",
        help="sim-to-real diagnosis: where the simulator departs from a recording, and why",
        description="Compare the simulator with a recording (candump log or contract CSV): "
        "where the gap lies, which unmodelled effect causes it (fitted), how far it shrinks.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--real", type=Path, required=True, metavar="REC", help="the recording")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE",
        help="simulator YAML (default: the shipped config/simulator.yaml)",
    )
    p.add_argument(
        "--json", type=output_file, required=True, metavar="F", help="write the report here"
    )
    p.add_argument(
        "--report",
        type=output_dir,
        default=None,
        metavar="DIR",
        help="also write PNG plots and summary.txt into DIR (created)",
    )
    p.add_argument(
        "--loop",
        default=None,
        metavar="NAME",
        help="diagnose this loop of a whole-machine recording (candump log or CSV of several "
        "loops' signals, read through --loops-config's dbc and loops:); the loops the "
        "single-loop simulator cannot stand for (the swing motor, loops sharing a "
        "load-sensing pump) are refused with one line, exit 3",
    )
    p.add_argument(
        "--loops-config",
        type=Path,
        default=None,
        metavar="FILE",
        help="with --loop: the monitor YAML naming the recording's DBC and loops (default: "
        "the shipped config/excavator4.yaml); the simulator is --config, else the loop's "
        "machine: key, else the shipped config/simulator.yaml",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run)


def _refuse_whole_machine(path: Path) -> None:
    """A recording of several loops read as one would be its boom alone: ask for --loop."""
    from monitor.offline.loopsniff import loops_in

    found = loops_in(path)
    if found:
        raise ConfigError(
            f"{path}: a whole-machine recording (it carries the {', '.join(found)} loops' "
            "signals of dbc/excavator4.dbc): the gap tool diagnoses one loop; give --loop NAME"
        )


def _read_loop(args: argparse.Namespace) -> tuple[MachineParams, Recording]:
    """--loop: the simulator and the loop's signals of the whole-machine recording, the loop
    checked (``monitor.gap.data.loop``) before the recording is read."""
    from monitor.gap.data.loop import gap_loop, loop_config, read_gap_loop

    cfg = loop_config(args.loops_config)
    loop = gap_loop(cfg, args.loop)
    if args.config is not None or loop.machine is None:
        machine = load_machine(args.config)
    else:
        machine = loop.machine
    return machine, read_gap_loop(args.real, cfg, args.loop)


def run(args: argparse.Namespace) -> int:
    from monitor.gap.diagnose import diagnose
    from monitor.gap.report.document import build_report
    from monitor.gap.report.summary import mechanism_line, summary_text

    if args.report is not None and args.report.exists() and not args.report.is_dir():
        raise ConfigError(f"--report {args.report}: exists and is not a directory")
    if args.loop is None:
        if args.loops_config is not None:
            raise ConfigError("--loops-config names a whole machine's loops: give --loop NAME")
        _refuse_whole_machine(args.real)
        machine = load_machine(args.config)
        rec = read_recording(args.real)
    else:
        machine, rec = _read_loop(args)

    def progress(msg: str) -> None:
        if not args.quiet:
            print(f"gap: {msg}", file=sys.stderr, flush=True)

    diag = diagnose(rec, machine, progress)
    report = build_report(diag, machine)
    text = summary_text(report)
    try:
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
        if args.report is not None:
            from monitor.gap.report.plots import write_plots

            args.report.mkdir(parents=True, exist_ok=True)
            (args.report / "summary.txt").write_text(text, encoding="utf-8")
            write_plots(diag, report, args.report)
    except OSError as exc:
        raise MonitorError(f"cannot write the report: {exc}") from None
    print(text.splitlines()[0])
    line = f"verdict: {report['verdict']}"
    if report["also"]:
        line += f" (also {report['also']})"
    print(
        f"{line}; confidence {report['confidence']:.2f}; held-out gap removed "
        f"{100 * report['shrink']['heldout_reduction']:.0f} %"
    )
    mechanism = mechanism_line(report)
    if mechanism:
        print(mechanism)
    return 0
