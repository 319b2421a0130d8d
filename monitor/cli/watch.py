"""``monitor watch``: a live terminal view of a running monitor, from the bus alone."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from monitor.errors import ConfigError

_REDRAW_S = 0.2


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "watch",
        help="live terminal view of a running monitor, from the bus (like cantools monitor)",
        description="Show, from the CAN bus alone, what the monitor reports: per loop the "
        "state, J / eps0 as a bar (| marks the threshold), the isolated fault and the alarm "
        "count (MON_Alarm); MON_Status (operating state, range and sensor checks, frame "
        "counters, bus events); the active J1939 DM1 trouble codes with their lamps; the "
        "decoded PP, PA, PB [bar] and QP [L/min] with frame and reject counts per message. "
        "It only listens, so it runs beside the daemon on the machine. q quits.",
    )
    p.add_argument(
        "--interface",
        default="socketcan",
        metavar="NAME",
        help="python-can interface (default socketcan)",
    )
    p.add_argument("--channel", default="can0", metavar="CHANNEL", help="default can0")
    p.add_argument(
        "--dbc",
        type=Path,
        default=None,
        metavar="FILE",
        help="DBC of the machine (default: the shipped one)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import curses

    from monitor.bus.reader import BusConfig, open_bus
    from monitor.codec.frames import FrameCodec
    from monitor.watch.state import WatchState

    if args.dbc is not None and not args.dbc.is_file():
        raise ConfigError(f"--dbc {args.dbc}: no such file")
    codec = FrameCodec.from_dbc(args.dbc)
    bus = open_bus(BusConfig(interface=args.interface, channel=args.channel))
    state = WatchState(codec)
    try:
        curses.wrapper(_loop, bus, state, f"{args.interface}:{args.channel}")
    finally:
        bus.shutdown()
    return 0


def _loop(screen, bus, state, source: str) -> None:  # pragma: no cover - drawn in a terminal
    import curses

    from monitor.watch.render import render

    curses.curs_set(0)
    screen.nodelay(True)
    next_draw = 0.0
    while True:
        msg = bus.recv(timeout=0.02)
        while msg is not None:
            state.feed(msg)
            msg = bus.recv(timeout=0)
        now = time.monotonic()
        if now >= next_draw:
            next_draw = now + _REDRAW_S
            height, width = screen.getmaxyx()
            screen.erase()
            for y, line in enumerate(render(state, source, now, width - 1)[: height - 1]):
                screen.addstr(y, 0, line)
            screen.refresh()
        key = screen.getch()
        if key in (ord("q"), ord("Q"), 27):
            return
