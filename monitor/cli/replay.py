"""``monitor replay LOG --bus CHANNEL``: put a candump log on a bus with its timing."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from monitor.bus.reader import BusConfig, open_bus
from monitor.bus.replay import replay_log
from monitor.errors import ConfigError


def _speed(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "replay",
        help="put a candump log on a CAN bus with the log's timing (like canplayer)",
        description="Send the frames of a candump -L log on a bus, spaced as in the log "
        "divided by --speed. The log's timestamps travel with the frames (a python-can "
        "virtual bus keeps them).",
    )
    p.add_argument("log", type=Path, metavar="LOG")
    p.add_argument("--bus", required=True, metavar="CHANNEL", help="e.g. can0, vcan0")
    p.add_argument(
        "--interface",
        default="socketcan",
        metavar="NAME",
        help="python-can interface (default socketcan)",
    )
    p.add_argument("--bitrate", type=int, default=500_000, help="for interfaces that set it")
    p.add_argument(
        "--speed",
        type=_speed,
        default=1.0,
        metavar="X",
        help="time factor: 2 plays twice as fast (default 1)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.log.is_file():
        raise ConfigError(f"{args.log}: no such file")
    bus = open_bus(BusConfig(interface=args.interface, channel=args.bus, bitrate=args.bitrate))
    start = time.monotonic()
    try:
        counts = replay_log(args.log, bus, args.speed)
    finally:
        bus.shutdown()
    span = (counts.last_ts or 0.0) - (counts.first_ts or 0.0)
    print(
        f"{args.log}: {counts.sent} frames on {args.interface}:{args.bus} in "
        f"{time.monotonic() - start:.1f} s (log span {span:.1f} s, speed {args.speed:g})"
        + (f"; {counts.send_errors} send errors" if counts.send_errors else "")
        + (f"; time went back {counts.time_jumps_back}x" if counts.time_jumps_back else ""),
        file=sys.stderr,
    )
    return 0
