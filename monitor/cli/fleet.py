"""``monitor fleet``: commission and judge a whole fleet on Dask (run), and its page (report)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from monitor.cli import _fleet_web
from monitor.cli._extras import require
from monitor.cli._paths import output_dir
from monitor.fleet.health import DRIFT_FLAG, DRIFT_LOGS


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fleet",
        help="judge every machine's logs on Dask; the fleet report",
        description="Fleet layout: FLEET/<machine>/commissioning/*.log|*.csv (optional) and "
        "FLEET/<machine>/logs/*.log|*.csv (file-name order is time order).",
    )
    sub = p.add_subparsers(dest="fleet_command", metavar="SUBCOMMAND")
    sub.required = True
    r = sub.add_parser(
        "run",
        help="train each machine's model, judge every new log, write Parquet results",
        description="Per machine, train its model from its commissioning data (as `monitor "
        "train --folds 4 --reference DEFAULT`: J's threshold cross-fitted over "
        "the whole run, never below the default model's; the bias statistic on only where "
        "its held-out data earns its threshold, as monitor train decides, the reason in "
        "models/<machine>.trained-from.json; without "
        "commissioning data the default model, and it says so), then judge every log not yet "
        "in RESULTS (by SHA-256) as `monitor detect` does. With a --config of several loops "
        "(config/excavator4.yaml: whole machines), a model per machine and loop (as `monitor "
        "train --loop`) and a row per log and loop (as `monitor detect --loop`); a loop "
        "without its machine's model is not judged. Writes RESULTS/logs.parquet, "
        "events.parquet and models/<machine>.model.npz. Runs on a Dask LocalCluster of "
        "--workers processes, or on an existing scheduler. Progress on stderr (redrawn on a "
        "terminal, a line every 30 s elsewhere); the last line counts the fleet's logs "
        "judged, not judged (read, nothing to judge) and failed (a row with its `error`), "
        "naming the first failures. Exit 0 when every log was read, whatever its verdict; 3 "
        "when any log failed; 130 on Ctrl-C, with the tables as before the run and the "
        "finished logs kept for the next run, which resumes.",
    )
    r.add_argument("fleet", type=Path, metavar="FLEET")
    r.add_argument("--out", type=output_dir, required=True, metavar="RESULTS")
    where = r.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        default=2,
        metavar="N",
        help="local Dask worker processes (default 2)",
    )
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786",
    )
    r.add_argument(
        "--model",
        type=Path,
        default=None,
        metavar="DEFAULT",
        help="model for machines without commissioning data, and the reference whose "
        "thresholds floor the commissioned ones (default: the shipped)",
    )
    r.add_argument("--config", type=Path, default=None, help="monitor YAML (default: shipped)")
    r.add_argument(
        "--isolation",
        choices=("sim", "none"),
        default="sim",
        help="as `monitor train --isolation` (default sim)",
    )
    r.set_defaults(func=run)
    rep = sub.add_parser(
        "report",
        help="the fleet page: Markdown (--out) and the web page (--html)",
        description="Read RESULTS/logs.parquet. --html DIR: the fleet web page, static "
        "files (DIR/index.html, a page per machine, the alarm list, plotly.min.js) that open "
        "from disk or any web server without a network connection. --out DIR: DIR/fleet.md "
        "with health.png "
        "(per log and machine the health index, the largest alarm level max(J/eps0, B/b0), "
        "with max and p95 of J/eps0; the alarm threshold drawn at 1.0) and timeline.png. "
        "The trend is Theil-Sen over each machine's last K judged logs; the crossing is the "
        "number of logs until it reaches 1.0, with its 90 % interval. The drift is the median "
        f"J of the last {DRIFT_LOGS} logs over the commissioning run's, whatever eps0 is "
        f"({DRIFT_FLAG:g} x and above: wearing?). The first warning is the first log, before "
        f"any alarm, at which the drift reached {DRIFT_FLAG:g} x (machines without a "
        "commissioning run: a bounded crossing forecast).",
    )
    rep.add_argument("results", type=Path, metavar="RESULTS")
    rep.add_argument(
        "--out",
        type=output_dir,
        default=None,
        metavar="DIR",
        help="the Markdown page with PNG pictures into DIR",
    )
    rep.add_argument(
        "--html",
        type=output_dir,
        default=None,
        metavar="DIR",
        help="the web page into DIR (index.html)",
    )
    rep.add_argument(
        "--last", type=int, default=6, metavar="K", help="logs in the trend (default 6)"
    )
    _fleet_web.add_page_options(rep)
    rep.set_defaults(func=report)
    _fleet_web.add_serve(sub)
    _fleet_web.add_query(sub)
    b = sub.add_parser(
        "bench",
        help="frames/s per worker: monitor detect, one process, Dask with 1 and 2 workers",
        description="Judge every log of FLEET (with the models of a finished run in RESULTS) "
        "with `monitor detect`'s code, as the fleet's task in one process, and on Dask "
        "LocalClusters of 1 and of 2 workers, in turn within each of --repeats rounds; "
        "print each one's median seconds, frames/s and frames/s per worker beside detect's "
        "as a table on stderr and JSON on stdout, with the load average.",
    )
    b.add_argument("fleet", type=Path, metavar="FLEET")
    b.add_argument("--results", type=Path, required=True, metavar="RESULTS")
    b.add_argument(
        "--repeats", type=int, default=3, metavar="N", help="timings of each way (default 3)"
    )
    b.add_argument(
        "--dask-default",
        action="store_true",
        help="also time clusters whose workers have Dask's default environment, as "
        "`dask worker` starts them (what the fleet's own workers save)",
    )
    b.set_defaults(func=bench)


def run(args: argparse.Namespace) -> int:
    require("distributed", "pyarrow", "scipy")  # the [fleet] extra, before any work
    from monitor.errors import ConfigError
    from monitor.fleet.progress import Progress
    from monitor.fleet.run import RunOptions, run_fleet

    if args.workers < 1:
        raise ConfigError(f"--workers {args.workers}: at least 1")
    if not args.fleet.is_dir():
        raise ConfigError(f"{args.fleet}: no such fleet folder")
    if (args.fleet / "logs").is_dir() or (args.fleet / "commissioning").is_dir():
        raise ConfigError(
            f"{args.fleet}: one machine's folder (it holds logs/ or "
            "commissioning/); give the fleet folder above it"
        )

    default_model = None if args.model is None else str(args.model.resolve())
    config = None if args.config is None else str(args.config.resolve())
    opts = RunOptions(
        workers=args.workers,
        scheduler=args.scheduler,
        default_model=default_model,
        config=config,
        isolation=args.isolation,
        loops=_loops(args.fleet, config, default_model),
    )
    progress = Progress(sys.stderr, tty=sys.stderr.isatty())
    outcome = run_fleet(args.fleet.resolve(), args.out, opts, progress)
    print(f"{outcome.line()}; rows in {args.out / 'logs.parquet'}", file=sys.stderr)
    return outcome.exit_code


def _loops(fleet: Path, config: str | None, default_model: str | None) -> tuple[str, ...]:
    """The loops each log is judged as (none: as one loop), or one line, before any work,
    for what cannot be judged so (``monitor.fleet.wholemachine``)."""
    from monitor.config.pump import load_pump
    from monitor.config.settings import load_config
    from monitor.fleet.layout import scan_fleet
    from monitor.fleet.wholemachine import fleet_loops

    cfg = load_config(None if config is None else Path(config))
    loops = [lc.name for lc in cfg.monitored_loops]
    # A config's `pump:` (a load-sensing pump, checked here) adds the pump as a row of its own.
    pump = len(loops) > 1 and load_pump(cfg) is not None
    return fleet_loops(scan_fleet(fleet.resolve()), loops, config, default_model, pump)


def report(args: argparse.Namespace) -> int:
    require("pyarrow", "matplotlib")
    from monitor.errors import ConfigError
    from monitor.fleet.report import write_report

    if args.last < 3:
        raise ConfigError("--last must be at least 3 logs")
    if args.out is None and args.html is None:
        raise ConfigError("give --out DIR (Markdown page) or --html DIR (web page), or both")
    if args.out is not None:
        page = write_report(args.results, args.out, args.last)
        print(f"wrote {page}", file=sys.stderr)
    if args.html is not None:
        print(f"wrote {_fleet_web.write_html(args)}", file=sys.stderr)
    unmerged = len(list((args.results / "parts").glob("*.json")))
    if unmerged:  # an interrupted or running `fleet run`: the page shows the tables only
        print(
            f"monitor fleet report: note: {unmerged} finished log(s) of an unfinished run "
            "are not in the tables yet (`monitor fleet run` again merges them)",
            file=sys.stderr,
        )
    return 0


def bench(args: argparse.Namespace) -> int:
    import json

    require("distributed")  # the [fleet] extra, before any work
    from monitor.errors import ConfigError
    from monitor.fleet.bench import bench_fleet, table

    if args.repeats < 1:
        raise ConfigError(f"--repeats {args.repeats}: at least 1")
    if not args.fleet.is_dir():
        raise ConfigError(f"{args.fleet}: no such fleet folder")
    out = bench_fleet(
        args.fleet.resolve(),
        args.results.resolve(),
        repeats=args.repeats,
        dask_default=args.dask_default,
    )
    print(table(out), file=sys.stderr)
    print(json.dumps(out, indent=2))
    return 0
