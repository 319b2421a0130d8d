"""``monitor simulate``: traces of the reference boom loop with faults and effects."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from monitor.cli._numbers import DURATION_MAX_S, DURATION_WHY, SEED_MAX, number
from monitor.cli._paths import output_file
from monitor.errors import ConfigError, MonitorError
from monitor.sim.cycles import CYCLES, make_cycle
from monitor.sim.effects import describe_catalogue, parse_effect
from monitor.sim.faults import parse_fault
from monitor.sim.machine import load_machine

_EPILOG = f"""\
faults (--fault NAME:SEV[@ONSET_S[+RAMP_S]], severity 0..1, abrupt at ONSET_S or ramped
linearly over RAMP_S seconds; repeatable):
  piston_wear   cylinder piston seal wear: internal leakage A<->B, up to 5e-12 m^3/(s Pa)
  spool_stroke  spool cannot reach full stroke: opening limited to (1 - 0.6 SEV)
  spool_wear    worn metering edges: leakage across every land like an opening of 0.1 SEV

effects (--effect NAME[:param=value,...], off unless given; repeatable):
{describe_catalogue()}

examples:
  monitor simulate --duration 600 --seed 1 --out normal.csv
  monitor simulate --duration 120 --seed 2 --fault piston_wear:0.5@60 --out wear.log
  monitor simulate --duration 60 --seed 3 --effect spool_dynamics:natural_freq_hz=8 --out s.csv
"""


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="simulate the boom loop (CSV or candump log at 100 Hz)",
        description="Simulate the reference excavator boom loop driven by a seeded command "
        "profile; write the contract CSV (.csv, with RodPos and internal states) or a candump "
        "log through the DBC (.log).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--duration", type=number(0.01, DURATION_MAX_S, unit="s", why=DURATION_WHY),
                   required=True, metavar="S",
                   help=f"length in seconds (at most {DURATION_MAX_S:g}: "
                   f"{DURATION_WHY})")  # fmt: skip
    p.add_argument(
        "--seed",
        type=number(0, SEED_MAX, whole=True),
        default=0,
        metavar="N",
        help="seed of the command profile and sensor noise (default 0)",
    )
    p.add_argument(
        "--cycle",
        choices=CYCLES,
        default="boom",
        help="boom: raise/hold/lower duty cycles (default); boom-cover: the same with twice "
        "the end-stop visits and the lever released anywhere around the stop, so spools "
        "close on trapped pressures (the shipped model's training data); ramp: slow spool "
        "triangles; step: spool steps",
    )
    p.add_argument("--fault", action="append", default=[], metavar="NAME:SEV[@ONSET_S[+RAMP_S]]")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:param=value,...]")
    p.add_argument(
        "--rod-pos",
        type=float,
        default=100.0,
        metavar="MM",
        help="initial rod position in mm from fully retracted (default 100)",
    )
    p.add_argument("--no-noise", action="store_true", help="noise-free sensors (still quantised)")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE",
        help="simulator YAML (default: the shipped config/simulator.yaml)",
    )
    p.add_argument("--out", type=output_file, required=True, metavar="FILE", help=".csv or .log")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.sim.simulate import simulate

    suffix = args.out.suffix.lower()
    if suffix not in (".csv", ".log"):
        raise ConfigError(f"--out {args.out}: expected a .csv or .log file name")
    faults = [parse_fault(text) for text in args.fault]
    effects = [parse_effect(text) for text in args.effect]
    machine = load_machine(args.config)
    if not 0.0 <= args.rod_pos <= machine.stroke_m * 1e3:
        raise ConfigError(
            f"--rod-pos {args.rod_pos:g} mm is outside the stroke 0..{machine.stroke_m * 1e3:g}"
        )
    for fault in faults:
        if fault.onset_s > args.duration:
            raise ConfigError(f"--fault {fault.name}: onset {fault.onset_s:g} s is after the end")
    start = time.perf_counter()
    commands = make_cycle(args.cycle, args.duration, args.seed)
    rec = simulate(
        commands,
        machine,
        faults,
        effects,
        seed=None if args.no_noise else args.seed,
        rod_pos0_m=args.rod_pos * 1e-3,
    )
    elapsed = time.perf_counter() - start
    try:
        if suffix == ".csv":
            from monitor.io.csvio import write_csv

            write_csv(args.out, rec)
            what = f"{len(rec)} rows"
        else:
            from monitor.codec.logwrite import write_candump

            counts = write_candump(args.out, rec)
            what = f"{sum(counts.values())} frames"
    except OSError as exc:
        raise MonitorError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    print(
        f"simulated {args.duration:g} s ({args.cycle}, seed {args.seed}) in {elapsed:.2f} s; "
        f"wrote {what} to {args.out}",
        file=sys.stderr,
    )
    return 0
