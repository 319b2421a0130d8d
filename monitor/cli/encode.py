"""``monitor encode CSV --out LOG``: a contract CSV to a candump log the DBC decodes."""

from __future__ import annotations

import argparse
from pathlib import Path

from monitor.cli._numbers import EPOCH_MAX_S, number
from monitor.cli._paths import output_file
from monitor.codec.frames import FrameCodec
from monitor.codec.logwrite import write_candump
from monitor.errors import ConfigError
from monitor.io.candump import DEFAULT_START_TIME_S
from monitor.io.csvio import read_csv

_DESCRIPTION = """\
Turn a contract CSV into a candump -L log with valid alive counters and CRC-8/SAE-J1850.

CSV columns (order free): t [s, increasing], SpoolCmd [%, -100..100], PumpDispCmd
[%, 0..100], EngineSpeed [rpm], OilTemp [degC], PP, PA, PB [bar, gauge], QP [L/min],
optionally RodPos [mm].  Frames: HYD_Pressures (PP, PA, PB), HYD_Flow (QP) and
HYD_Commands (SpoolCmd, PumpDispCmd, EngineSpeed) every 10 ms row, HYD_RodPos when the
CSV has RodPos, HYD_OilTemp once a second.  Values beyond the DBC ranges are clipped
(sensor saturation); an empty field skips the frame that carries it (missing data).
"""


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "encode",
        help="contract CSV -> candump log (DBC frames with counters and CRC)",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("csv", metavar="CSV", type=Path, help="contract CSV of physical signals")
    p.add_argument(
        "--out", metavar="LOG", type=output_file, required=True, help="candump log to write"
    )
    p.add_argument(
        "--dbc", metavar="FILE", type=Path, default=None, help="DBC file (default: the shipped one)"
    )
    p.add_argument(
        "--start-time",
        metavar="S",
        type=number(0, EPOCH_MAX_S, unit="s"),
        default=DEFAULT_START_TIME_S,
        help=f"log time of t = 0 [s since the Unix epoch] (default {DEFAULT_START_TIME_S:.0f})",
    )
    p.add_argument("--channel", default="can0", help="interface name in the log (default can0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.channel or any(c.isspace() for c in args.channel):
        raise ConfigError(f"--channel {args.channel!r}: must be one word such as can0")
    if args.start_time < 0:
        raise ConfigError(f"--start-time {args.start_time}: must be >= 0 s")
    codec = FrameCodec.from_dbc(args.dbc)
    rec = read_csv(args.csv)
    counts = write_candump(args.out, rec, codec, start_time_s=args.start_time, channel=args.channel)
    total = sum(counts.values())
    per_message = ", ".join(f"{name} {n}" for name, n in counts.items())
    print(f"{args.out}: {total} frames from {len(rec)} rows ({per_message})")
    return 0
