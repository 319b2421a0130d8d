"""``monitor simulate-fleet``: a simulated fleet in the fleet layout, with its answer key."""

from __future__ import annotations

import argparse
import sys

from monitor.cli._paths import output_dir
from monitor.cli.simulate import MACHINES
from monitor.errors import ConfigError


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate-fleet",
        help="write a simulated fleet (FLEET/<machine>/commissioning|logs) and its answer key",
        description="Simulate N machines drawn within +-5 % of the reference, each with "
        "its commissioning log and one candump log a day or --logs-per-day (one oil "
        "temperature per day). M01 wears its piston seal and M02 its spool slowly (severity 0 "
        "in the first log rising to --wear-max in the last), M03's flow sensor freezes from "
        "the middle day on; the rest are healthy. OUT/answer_key.json says which is which. "
        "--machine excavator4: whole machines instead (every loop's signals of "
        "dbc/excavator4.dbc in each log, one duty cycle per log drawn from mixed, "
        "truck-loading and lifting); M01 wears its stick's piston seal, M02 its bucket's "
        "spool, M03 its swing motor and M04 its pump, the rest are healthy.",
    )
    p.add_argument("out", type=output_dir, metavar="OUT", help="fleet folder to write (created)")
    p.add_argument(
        "--machines",
        type=int,
        required=True,
        metavar="N",
        help="machines to simulate (M01, M02, ...; roles as above)",
    )
    p.add_argument("--days", type=int, required=True, metavar="D", help="days of logs per machine")
    p.add_argument(
        "--logs-per-day",
        type=int,
        default=1,
        metavar="L",
        help="logs per machine and day (default 1: dayDD.log; more: dayDD-1.log, "
        "dayDD-2.log, ..., as a machine that uploads after every few hours)",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="default 0")
    p.add_argument(
        "--machine",
        choices=MACHINES,
        default=None,
        help="a fleet of whole machines (excavator4: boom, stick, bucket and swing on one "
        "load-sensing pump, config/excavator4_sim.yaml) instead of single boom loops",
    )
    p.add_argument(
        "--log-s",
        type=float,
        default=300.0,
        metavar="S",
        help="length of each daily log in seconds (default 300)",
    )
    p.add_argument(
        "--commissioning-s",
        type=float,
        default=1200.0,
        metavar="S",
        help="length of each machine's commissioning log in seconds (default 1200)",
    )
    p.add_argument(
        "--wear-max",
        type=float,
        default=0.6,
        metavar="SEV",
        help="severity of the wearing machines in the last log, rising linearly from 0 in "
        "the first (default 0.6; a slow wear such as 0.2 over 8 days shows the prognosis "
        "before the alarm)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.machines < 1 or args.days < 1:
        raise ConfigError("--machines and --days must be at least 1")
    if not 1 <= args.logs_per_day <= 24:
        raise ConfigError(f"--logs-per-day must be 1..24, got {args.logs_per_day}")
    if args.days * args.logs_per_day > 999:
        raise ConfigError("--days x --logs-per-day must be at most 999 logs per machine")
    if args.log_s < 60 or args.commissioning_s < 180:
        raise ConfigError(
            "--log-s must be at least 60 s and --commissioning-s at least 180 s "
            "(the J window is 30 s)"
        )
    if not 0.0 <= args.wear_max <= 1.0:
        raise ConfigError(f"--wear-max must be a severity in [0, 1], got {args.wear_max:g}")
    if args.out.exists() and any(args.out.iterdir()):
        raise ConfigError(f"{args.out}: exists and is not empty")
    from monitor.fleet.simulate import FleetPlan

    def say(message: str) -> None:
        print(message, file=sys.stderr)

    plan = FleetPlan(
        args.machines,
        args.days,
        args.seed,
        args.log_s,
        args.commissioning_s,
        wear_max=args.wear_max,
        logs_per_day=args.logs_per_day,
    )
    if args.machine is None:
        from monitor.fleet.simulate import simulate_fleet

        simulate_fleet(args.out, plan, say=say)
    else:
        from monitor.fleet.simulate_whole import simulate_whole_fleet

        simulate_whole_fleet(args.out, plan, say=say)
    what = "machines" if args.machine is None else f"{args.machine} machines"
    print(
        f"wrote {args.machines} {what} x {args.days} days x {args.logs_per_day} log(s) "
        f"to {args.out}",
        file=sys.stderr,
    )
    return 0
