"""``monitor run``: the daemon, until SIGTERM/SIGINT; SIGHUP reloads config and model."""

from __future__ import annotations

import argparse
import logging
import signal
import time
from pathlib import Path
from types import FrameType

from monitor.config import load_config
from monitor.daemon import Daemon, setup_logging

log = logging.getLogger("monitor")


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run",
        help="the live monitor daemon on a CAN bus",
        description="Read the sensor frames from the bus of config/monitor.yaml, detect at "
        "100 Hz and send MON_Alarm / MON_Status frames; events go to the event log, raw "
        "frames around each alarm to the black box. SIGTERM/SIGINT stop it cleanly, SIGHUP "
        "reloads config and model without closing the bus. Logs to stderr for journald.",
    )
    p.add_argument("--config", type=Path, default=None, help="monitor YAML (default: shipped)")
    p.add_argument("--verbose", action="store_true", help="debug logging (every bad frame)")
    p.set_defaults(func=run)


class _Flags:
    """Set by signal handlers, read by the main loop: handlers do nothing else."""

    stop = False
    reload = False


def run(args: argparse.Namespace) -> int:
    setup_logging(logging.DEBUG if args.verbose else logging.INFO)
    cfg = load_config(args.config)
    flags = _Flags()

    def on_stop(signum: int, frame: FrameType | None) -> None:
        flags.stop = True

    def on_hup(signum: int, frame: FrameType | None) -> None:
        flags.reload = True

    signal.signal(signal.SIGTERM, on_stop)
    signal.signal(signal.SIGINT, on_stop)
    signal.signal(signal.SIGHUP, on_hup)
    daemon = Daemon(cfg)
    daemon.start()
    try:
        while not flags.stop:
            if flags.reload:
                flags.reload = False
                log.info("SIGHUP: reloading %s", cfg.source)
                daemon.request_reload()
            if not daemon.healthy:
                log.error("a monitor thread died; stopping so the service manager restarts us")
                return 1
            time.sleep(0.1)
    finally:
        daemon.stop()  # ordered: reader, detector, outputs (fsynced), bus
    return 0
