"""``monitor fleet report --html``, ``fleet serve`` and ``fleet query``: the fleet web page
and SQL over the results (registered by ``monitor.cli.fleet``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_page_options(p: argparse.ArgumentParser) -> None:
    """What the web page needs besides RESULTS (report --html and serve)."""
    p.add_argument(
        "--fleet",
        type=Path,
        default=None,
        metavar="FLEET",
        help="the fleet folder the results were judged from: each machine page "
        "then plots the signals and statistics around its alarms, read from the "
        "log itself (without it, no signal plots)",
    )
    p.add_argument(
        "--config", type=Path, default=None, help="monitor YAML the run used (default: shipped)"
    )


def add_serve(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser(
        "serve",
        help="the fleet web page, live on localhost, with acknowledge and shelve",
        description="Serve the fleet web page of RESULTS (as `fleet report --html`) on "
        "http://127.0.0.1:PORT/ until Ctrl-C. The alarm list there acknowledges and shelves "
        "alarm episodes, with who and when, in RESULTS/alarm-acks.jsonl (appended, never "
        "in the Parquet tables).",
    )
    s.add_argument("results", type=Path, metavar="RESULTS")
    s.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0: any)")
    s.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1, this machine only)",
    )
    s.add_argument("--last", type=int, default=6, metavar="K", help="logs in the trend (default 6)")
    add_page_options(s)
    s.set_defaults(func=serve)


def add_query(sub: argparse._SubParsersAction) -> None:
    q = sub.add_parser(
        "query",
        help="SQL over the results (DuckDB): tables logs, events, episodes",
        description="Run one DuckDB SQL statement over RESULTS and print the result as a "
        "table. Views: logs (RESULTS/logs.parquet), events (events.parquet) and episodes "
        "(one row per alarm episode: machine, log, kind, name, check, start_t, end_t, "
        "duration_s, spn, fmi, open; and loop for whole machines). Recipes: "
        "docs/how-to/fleet.md.",
    )
    q.add_argument("results", type=Path, metavar="RESULTS")
    q.add_argument("sql", metavar="SQL")
    q.add_argument("--csv", action="store_true", help="print CSV instead of a table")
    q.set_defaults(func=query)


def write_html(args: argparse.Namespace) -> Path:
    from monitor.fleet.report import load_rows
    from monitor.fleet.web import Site

    site = Site(args.results, load_rows(args.results), _fleet(args), _config(args), args.last)
    return site.write(args.html)


def _fleet(args: argparse.Namespace) -> Path | None:
    from monitor.errors import ConfigError

    if args.fleet is not None and not args.fleet.is_dir():
        raise ConfigError(f"--fleet {args.fleet}: no such fleet folder")
    return args.fleet


def _config(args: argparse.Namespace) -> str | None:
    return None if args.config is None else str(args.config.resolve())


def serve(args: argparse.Namespace) -> int:
    from monitor.errors import ConfigError
    from monitor.fleet.report import load_rows
    from monitor.fleet.serve import serve_site
    from monitor.fleet.web import Site

    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port {args.port}: 0..65535")
    if args.last < 3:
        raise ConfigError("--last must be at least 3 logs")
    site = Site(args.results, load_rows(args.results), _fleet(args), _config(args), args.last)
    return serve_site(
        site, args.host, args.port, say=lambda m: print(m, file=sys.stderr, flush=True)
    )


def query(args: argparse.Namespace) -> int:
    from monitor.fleet.query import run_query

    header, rows = run_query(args.results, args.sql)
    if args.csv:
        import csv

        w = csv.writer(sys.stdout)
        w.writerow(header)
        w.writerows(rows)
    else:
        from monitor.fleet.query import format_table

        print(format_table(header, rows))
    return 0
