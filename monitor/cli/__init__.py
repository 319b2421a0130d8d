"""``monitor`` command line: one module per subcommand, each with ``add_subparser``."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from monitor import __version__
from monitor.errors import MonitorError

# Subcommand modules, in the order --help lists them.  Each defines
# ``add_subparser(subparsers)`` which registers its parser and sets ``func``.
_SUBCOMMANDS = ("simulate", "encode")


class _Parser(argparse.ArgumentParser):
    """argparse that exits 2 with one line, as the command contract asks."""

    def error(self, message: str) -> None:  # noqa: D102 - argparse API
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="monitor",
        description="Hydraulic fault monitor for an excavator loop on CAN.",
    )
    parser.add_argument("--version", action="version", version=f"monitor {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in _SUBCOMMANDS:
        importlib.import_module(f"monitor.cli.{name}").add_subparser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MonitorError as exc:
        print(f"monitor {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"monitor {args.command}: interrupted", file=sys.stderr)
        return 130
