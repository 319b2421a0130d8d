"""``monitor`` command line: one module per subcommand, each with ``add_subparser``."""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Sequence
from typing import NoReturn

from monitor import __version__
from monitor.cli._extras import missing_extra
from monitor.errors import MonitorError

# Every module of this package defines ``add_subparser(subparsers)``, which registers its
# parser and sets ``func``.  --help lists these first, in this order, then any others.
_ORDER = (
    "demo",
    "run",
    "detect",
    "train",
    "replay",
    "watch",
    "simulate",
    "encode",
    "gap",
    "eval_sim",
    "eval_uci",
    "bench",
    "warm_up",
    "build_controller",
)


def _subcommand_modules() -> list[str]:
    found = {m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")}
    return [n for n in _ORDER if n in found] + sorted(found - set(_ORDER))


class _Parser(argparse.ArgumentParser):
    """argparse that exits 2 with one line, as the command contract asks."""

    def error(self, message: str) -> NoReturn:  # noqa: D102 - argparse API
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser; with ``only`` (a subcommand's module name) just that subcommand."""
    parser = _Parser(
        prog="monitor",
        description="Hydraulic fault monitor for an excavator loop on CAN.",
    )
    parser.add_argument("--version", action="version", version=f"monitor {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    names = _subcommand_modules()
    for name in [only] if only in names else names:
        importlib.import_module(f"monitor.cli.{name}").add_subparser(sub)
    return parser


class _OneLine(logging.Formatter):
    def __init__(self, command: str) -> None:
        super().__init__(f"monitor {command}: %(levelname)s: %(message)s")

    def format(self, record: logging.LogRecord) -> str:
        record.levelname = record.levelname.lower()
        return super().format(record)


def _warnings_to_stderr(command: str) -> None:
    """Warnings of the library (a torn log line, ...) as one line each on stderr."""
    logger = logging.getLogger("monitor")
    for h in logger.handlers:
        if getattr(h, "_monitor_cli", False):
            logger.removeHandler(h)  # a second main() in one process (tests): a fresh stream
    handler = logging.StreamHandler(sys.stderr)
    handler.setLevel(logging.WARNING)
    handler.setFormatter(_OneLine(command))
    handler._monitor_cli = True  # type: ignore[attr-defined]
    logger.addHandler(handler)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # Import only the subcommand asked for: the others pull in the simulator, scipy and
    # matplotlib, seconds of start-up on a controller (minutes in the SocketCAN test VM).
    first = argv[0].replace("-", "_") if argv and not argv[0].startswith("-") else None
    try:
        return _main(argv, first)
    except ModuleNotFoundError as exc:  # a command of an extra on the controller's install
        line = missing_extra(exc)
        if line is None:
            raise
        print(f"monitor{f' {argv[0]}' if first else ''}: error: {line}", file=sys.stderr)
        return 2


def _main(argv: list[str], first: str | None) -> int:
    parser = build_parser(first)
    if not argv:  # `monitor` alone: what it can do, as with --help, but a usage error
        parser.print_help(sys.stderr)
        return 2
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0), a usage error (2): argparse already printed it
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    if args.command not in ("run", "demo"):  # those two log to the journal their own way
        _warnings_to_stderr(args.command)
    try:
        return int(args.func(args) or 0)
    except MonitorError as exc:
        print(f"monitor {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt as exc:  # with a message when the command stopped in order
        why = f": {exc}" if str(exc) else ""
        print(f"monitor {args.command}: interrupted{why}", file=sys.stderr)
        return 130
