"""``monitor run``: the daemon, until SIGTERM/SIGINT; SIGHUP reloads config and model.

Under systemd (``Type=notify``) it reports READY=1 once the bus is open and the model
loaded, WATCHDOG=1 every WatchdogSec/2 while the detector loop is alive and turning,
RELOADING=1 then READY=1 around a SIGHUP reload, and STOPPING=1 before the ordered stop.
"""

from __future__ import annotations

import argparse
import logging
import signal
import time
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the daemon is imported when it runs: `monitor --help` stays light
    from monitor.live.daemon import Daemon
    from monitor.live.sdnotify import Notifier

log = logging.getLogger("monitor")


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run",
        help="the live monitor daemon on a CAN bus",
        description="Read the sensor frames from the bus of config/monitor.yaml, detect at "
        "100 Hz and send MON_Alarm / MON_Status frames; events go to the event log, raw "
        "frames around each alarm to the black box. SIGTERM/SIGINT stop it cleanly, SIGHUP "
        "reloads config and model without closing the bus. Logs to stderr for journald; "
        "speaks the systemd notify protocol when NOTIFY_SOCKET is set (Type=notify, "
        "WatchdogSec).",
    )
    p.add_argument("--config", type=Path, default=None, help="monitor YAML (default: shipped)")
    p.add_argument("--verbose", action="store_true", help="debug logging (every bad frame)")
    p.set_defaults(func=run)


class _Flags:
    """Set by signal handlers, read by the main loop: handlers do nothing else."""

    stop = False
    reload = False


def run(args: argparse.Namespace) -> int:
    from monitor.config.settings import load_config
    from monitor.live.daemon import Daemon
    from monitor.live.journal import setup_logging
    from monitor.live.sdnotify import Notifier

    cfg = load_config(args.config)  # a bad file is one line from the CLI, before any logging
    setup_logging(logging.DEBUG if args.verbose else logging.INFO)
    flags = _install_handlers()
    daemon = Daemon(cfg)
    daemon.start()
    notifier = Notifier()
    where = f"monitoring {cfg.bus.interface}:{cfg.bus.channel}"
    notifier.ready(where)
    _log_start_up()
    try:
        if not _supervise(daemon, flags, notifier, where, cfg.source):
            return 1
    finally:
        notifier.stopping()
        daemon.stop()  # ordered: reader, detector, outputs (fsynced), bus
        notifier.close()
    if daemon.unwritten:
        log.error(
            "%d event(s) could not be written to %s (see the errors above)",
            daemon.unwritten,
            cfg.event_log.path,
        )
        return 1
    return 0


def _install_handlers() -> _Flags:
    """SIGTERM and SIGINT ask for the stop, SIGHUP for a reload: flags only."""
    flags = _Flags()

    def on_stop(signum: int, frame: FrameType | None) -> None:
        flags.stop = True

    def on_hup(signum: int, frame: FrameType | None) -> None:
        flags.reload = True

    signal.signal(signal.SIGTERM, on_stop)
    signal.signal(signal.SIGINT, on_stop)
    signal.signal(signal.SIGHUP, on_hup)
    return flags


def _supervise(daemon: Daemon, flags: _Flags, notifier: Notifier, where: str, source: Path) -> bool:
    """The main loop until a stop is asked for (True) or a monitor thread died (False):
    reloads on request, RELOADING=1 then READY=1 around them, watchdog pings."""
    # Half the watchdog timeout between pings; a detector loop that has not turned for
    # that long is stuck, and the missing ping lets systemd restart us.
    ping_s = notifier.watchdog_s / 2 if notifier.watchdog_s else None
    last_ping = -float("inf")
    reload_seen: int | None = None  # reload_attempts before the pending reload
    while not flags.stop:
        if flags.reload:
            flags.reload = False
            log.info("SIGHUP: reloading %s", source)
            notifier.reloading()
            reload_seen = daemon.reload_attempts
            daemon.request_reload()
        if reload_seen is not None and daemon.reload_attempts > reload_seen:
            reload_seen = None
            notifier.ready(where)
        if not daemon.healthy:
            log.error("a monitor thread died; stopping so the service manager restarts us")
            return False
        now = time.monotonic()
        if ping_s is not None and now - last_ping >= ping_s:
            last_ping = now
            _ping(notifier, now - daemon.loop_mono, ping_s)
        time.sleep(min(0.1, ping_s or 0.1))
    return True


def _ping(notifier: Notifier, stalled_s: float, ping_s: float) -> None:
    """WATCHDOG=1 unless the detector loop has not turned for ``ping_s``."""
    if stalled_s < ping_s:
        notifier.watchdog()
    else:
        log.warning("detector loop stalled for %.1f s; no watchdog ping", stalled_s)


def _log_start_up() -> None:
    """How long start-up took, and whether warm-up spared the compiling: the tick's kernels
    ahead of time (numba never loaded), or numba's cache."""
    from monitor import STARTED_MONO
    from monitor.jit import cache_stats, numba_loaded

    took = time.monotonic() - STARTED_MONO
    if not numba_loaded():
        log.info(
            "ready %.2f s after the start; tick kernels compiled ahead of time (numba not loaded)",
            took,
        )
        return
    s = cache_stats()
    hint = " (run `monitor warm-up` once after an install)"
    log.info(
        "ready %.2f s after the start; numba kernels: %d loaded from the cache, %d compiled%s",
        took,
        s["hits"],
        s["misses"],
        hint,
    )
