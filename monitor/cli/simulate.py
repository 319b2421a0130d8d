"""``monitor simulate``: traces of the reference boom loop with faults and effects, or of the
whole excavator (``--machine excavator4``: every loop of dbc/excavator4.dbc)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from monitor.cli._numbers import DURATION_MAX_S, DURATION_WHY, SEED_MAX, number
from monitor.cli._paths import output_file
from monitor.errors import ConfigError, MonitorError
from monitor.io.recording import Recording
from monitor.sim.cycles import CYCLES, make_cycle
from monitor.sim.effects import describe_catalogue, parse_effect
from monitor.sim.faults import parse_fault
from monitor.sim.machine import load_machine
from monitor.sim.whole.cycles import TRAINING_CYCLES, WHOLE_CYCLES

MACHINES = ("excavator4",)
#: --oil-temp's range (degC): a mobile machine's oil from a cold start to its hottest.
OIL_TEMP_MIN_C, OIL_TEMP_MAX_C = -20.0, 120.0

_EPILOG = f"""\
faults (--fault NAME:SEV[@ONSET_S[+RAMP_S]], severity 0..1, abrupt at ONSET_S or ramped
linearly over RAMP_S seconds; repeatable):
  piston_wear   cylinder piston seal wear: internal leakage A<->B, up to 5e-12 m^3/(s Pa)
  spool_stroke  spool cannot reach full stroke: opening limited to (1 - 0.6 SEV)
  spool_wear    worn metering edges: leakage across every land like an opening of 0.1 SEV

effects (--effect NAME[:param=value,...], off unless given; repeatable):
{describe_catalogue()}

whole machine (--machine excavator4: boom, stick, bucket and swing on one load-sensing pump,
every loop's signals of dbc/excavator4.dbc; --cycle mixed (default), truck-loading, lifting;
dig-lift, truck loading whose lift starts at every phase of the stick's dig move's end,
return-to-stop, truck loading whose return sets the boom down onto its bottom stop as
the swing brakes, rest-on-stop, truck loading whose return lowers the boom onto its
stop, the lever let go as the rod lands, and swing-stop, short fast swings let go to centre
at once between truck loads, are for training data):
  --fault LOOP.FAULT:SEV[@ONSET_S[+RAMP_S]], LOOP.FAULT one of
    boom, stick, bucket: piston_wear, spool_stroke, spool_wear (as above)
    swing: spool_stroke, spool_wear, motor_leakage
    pump: pump_wear
  motor_leakage  swing motor internal leakage A<->B, up to 7e-12 m^3/(s Pa)
  pump_wear      leakage of the pump every loop shares, up to 8.3e-12 m^3/(s Pa)

examples:
  monitor simulate --duration 600 --seed 1 --out normal.csv
  monitor simulate --duration 120 --seed 2 --fault piston_wear:0.5@60 --out wear.log
  monitor simulate --duration 60 --seed 3 --effect spool_dynamics:natural_freq_hz=8 --out s.csv
  monitor simulate --duration 300 --seed 5 --oil-temp 25:55 \\
      --effect oil_viscosity:pump_leak_lpm_per_100bar=3 --out thin_oil_warm_up.csv
  monitor simulate --machine excavator4 --duration 600 --seed 4 --cycle truck-loading \\
      --fault stick.piston_wear:0.5@300 --out whole.log
"""


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="simulate the boom loop (CSV or candump log at 100 Hz)",
        description="Simulate the reference excavator boom loop driven by a seeded command "
        "profile; write the contract CSV (.csv, with RodPos and internal states) or a candump "
        "log through the DBC (.log); with --machine excavator4, the whole machine's loops.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--duration",
        type=number(0.01, DURATION_MAX_S, unit="s", why=DURATION_WHY),
        required=True,
        metavar="S",
        help=f"length in seconds (at most {DURATION_MAX_S:g}: {DURATION_WHY})",
    )
    p.add_argument(
        "--seed",
        type=number(0, SEED_MAX, whole=True),
        default=0,
        metavar="N",
        help="seed of the command profile and sensor noise (default 0)",
    )
    p.add_argument(
        "--machine",
        choices=MACHINES,
        default=None,
        help="simulate the whole machine (excavator4: boom, stick, bucket, swing on one "
        "load-sensing pump, the frames of dbc/excavator4.dbc) instead of the boom loop",
    )
    p.add_argument(
        "--cycle",
        choices=CYCLES + WHOLE_CYCLES + TRAINING_CYCLES,
        default=None,
        help="boom: raise/hold/lower duty cycles (default); boom-cover: the same with twice "
        "the end-stop visits and the lever released anywhere around the stop, so spools "
        "close on trapped pressures (the shipped model's training data); ramp: slow spool "
        "triangles; step: spool steps.  With --machine: mixed (default: blocks of both), "
        "truck-loading, lifting; dig-lift: truck loading whose lift starts at every phase of "
        "the stick's dig move's end; return-to-stop: truck loading whose return sets the boom "
        "down onto its bottom stop as the swing brakes; rest-on-stop: truck loading whose "
        "return lowers the boom onto its stop, the lever let go as the rod lands; swing-stop: "
        "short fast swings let go to centre at once between truck loads (all four training "
        "data)",
    )
    p.add_argument("--fault", action="append", default=[], metavar="NAME:SEV[@ONSET_S[+RAMP_S]]")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:param=value,...]")
    p.add_argument(
        "--rod-pos",
        type=float,
        default=None,
        metavar="MM",
        help="initial rod position in mm from fully retracted (default 100)",
    )
    p.add_argument(
        "--oil-temp",
        type=_oil_temp,
        default=None,
        metavar="C[:C_END]",
        help="oil temperature in degC, held (C) or warming linearly from C to C_END over the "
        "run (a warm-up: 25:55), within -20..120 (default: a warm machine, 40-60 degC drifting "
        "a degree or two, drawn from the seed)",
    )
    p.add_argument("--no-noise", action="store_true", help="noise-free sensors (still quantised)")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE",
        help="simulator YAML (default: the shipped config/simulator.yaml; with --machine "
        "config/excavator4_sim.yaml)",
    )
    p.add_argument("--out", type=output_file, required=True, metavar="FILE", help=".csv or .log")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.sim.simulate import simulate

    suffix = args.out.suffix.lower()
    if suffix not in (".csv", ".log"):
        raise ConfigError(f"--out {args.out}: expected a .csv or .log file name")
    if args.machine is not None:
        return _run_machine(args, suffix)
    if args.cycle is None:
        args.cycle = "boom"
    elif args.cycle not in CYCLES:
        raise ConfigError(
            f"--cycle {args.cycle} is a whole-machine cycle: add --machine excavator4"
        )
    if args.rod_pos is None:
        args.rod_pos = 100.0
    faults = [parse_fault(text) for text in args.fault]
    effects = [parse_effect(text) for text in args.effect]
    machine = load_machine(args.config)
    stroke_mm = machine.cylinder.stroke_m * 1e3
    if not 0.0 <= args.rod_pos <= stroke_mm:
        raise ConfigError(f"--rod-pos {args.rod_pos:g} mm is outside the stroke 0..{stroke_mm:g}")
    for fault in faults:
        if fault.onset_s > args.duration:
            raise ConfigError(f"--fault {fault.name}: onset {fault.onset_s:g} s is after the end")
    start = time.perf_counter()
    commands = make_cycle(args.cycle, args.duration, args.seed)
    if args.oil_temp is not None:
        first, last = args.oil_temp
        t = commands.t - commands.t[0]
        commands.columns["OilTemp"] = first + (last - first) * t / max(float(t[-1]), 1e-9)
    rec = simulate(
        commands,
        machine,
        faults,
        effects,
        seed=None if args.no_noise else args.seed,
        rod_pos0_m=args.rod_pos * 1e-3,
    )
    elapsed = time.perf_counter() - start
    what = _write(args.out, suffix, rec)
    print(
        f"simulated {args.duration:g} s ({args.cycle}, seed {args.seed}) in {elapsed:.2f} s; "
        f"wrote {what} to {args.out}",
        file=sys.stderr,
    )
    return 0


def _oil_temp(text: str) -> tuple[float, float]:
    """``C`` or ``C:C_END`` (degC): the oil held at C, or warming from C to C_END."""
    parse = number(OIL_TEMP_MIN_C, OIL_TEMP_MAX_C, unit="degC")
    parts = text.split(":")
    if len(parts) > 2:
        raise argparse.ArgumentTypeError(f"expected C or C:C_END in degC, got {text[:40]!r}")
    ends = [float(parse(part)) for part in parts]
    return ends[0], ends[-1]


def _write(out: Path, suffix: str, rec: Recording, dbc: Path | None = None) -> str:
    """``rec`` as the contract CSV or as a candump log through ``dbc`` (default: the shipped
    monitor.dbc); what was written, for the closing line."""
    try:
        if suffix == ".csv":
            from monitor.io.csvio import write_csv

            write_csv(out, rec)
            return f"{len(rec)} rows"
        from monitor.codec.frames import FrameCodec
        from monitor.codec.logwrite import write_candump

        codec = None if dbc is None else FrameCodec.from_dbc(dbc)
        counts = write_candump(out, rec, codec=codec)
        return f"{sum(counts.values())} frames"
    except OSError as exc:
        raise MonitorError(f"cannot write {out}: {exc.strerror or exc}") from None


def _run_machine(args: argparse.Namespace, suffix: str) -> int:
    """``--machine excavator4``: every loop's DBC signals in one CSV or candump log."""
    from monitor.resources import resource_path
    from monitor.sim.whole.cycles import make_whole_cycle
    from monitor.sim.whole.faults import parse_machine_fault
    from monitor.sim.whole.landing import release_on_landing
    from monitor.sim.whole.params import load_whole_machine
    from monitor.sim.whole.simulate import simulate_whole

    if args.cycle is None:
        args.cycle = "mixed"
    elif args.cycle not in WHOLE_CYCLES + TRAINING_CYCLES:
        raise ConfigError(
            f"--cycle {args.cycle} is a boom-loop cycle; the whole machine "
            f"runs {', '.join(WHOLE_CYCLES + TRAINING_CYCLES)}"
        )
    if args.effect:
        raise ConfigError("--effect is not available with --machine yet (the boom loop's only)")
    if args.oil_temp is not None:
        raise ConfigError("--oil-temp is the boom loop's; the whole machine draws its own")
    if args.rod_pos is not None:
        raise ConfigError("--rod-pos is the boom loop's; the whole machine starts at 30 % stroke")
    faults = [parse_machine_fault(text) for text in args.fault]
    for fault in faults:
        if fault.onset_s > args.duration:
            raise ConfigError(f"--fault {fault.label}: onset {fault.onset_s:g} s is after the end")
    machine = load_whole_machine(args.config)
    start = time.perf_counter()
    commands = make_whole_cycle(args.cycle, args.duration, args.seed, machine)
    if args.cycle == "rest-on-stop":
        commands = release_on_landing(commands, machine, args.seed)
    rec = simulate_whole(commands, machine, faults, seed=None if args.no_noise else args.seed)
    elapsed = time.perf_counter() - start
    what = _write(args.out, suffix, rec, dbc=resource_path("dbc", "excavator4.dbc"))
    print(
        f"simulated {args.duration:g} s of excavator4 ({args.cycle}, seed {args.seed}) in "
        f"{elapsed:.2f} s; wrote {what} to {args.out}",
        file=sys.stderr,
    )
    return 0
