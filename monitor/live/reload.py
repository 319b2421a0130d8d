"""SIGHUP: a new config and model, prepared off the detector thread.

``prepare`` parses the config, loads the models that changed and opens a new event log if
its path changed; it runs on a thread of its own (``Reloader``), so a slow or hostile file
never stalls detection, and the detector swaps the result in between two frames
(``swap_in``).  A loop whose model file (SHA-256) and ticker settings are
unchanged keeps its ticker: its J window and alarm state go on.  Otherwise the new ticker
takes over the running alarm state (``Ticker.carry_over``).  What a reload cannot change
(the loops' layout, bus, DBC, J1939) waits for a restart.  A reload not parsed within
``RELOAD_LIMIT_S`` is given up: its result, if it ever comes, is dropped, and the next
SIGHUP (or one that came meanwhile) starts a reload of its own, so one hung reload (a file
on a dead network mount) never disables SIGHUP until a restart.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, NamedTuple

from monitor.config.settings import MonitorConfig, load_config
from monitor.detection.ticker import Ticker
from monitor.io.digest import sha256_file
from monitor.live.disk import DiskOutputs
from monitor.live.eventlog import EventLog
from monitor.live.loops import Loop
from monitor.live.storage import Quota
from monitor.model.modelfile import MonitorModel

log = logging.getLogger("monitor")

RELOAD_LIMIT_S = 30.0  # a reload not parsed by then is given up


class Reload(NamedTuple):
    cfg: MonitorConfig
    loaded: list[tuple[MonitorModel, Ticker, str] | None]  # per loop; None: keep it
    event_log: EventLog | None  # a new event log path, opened


def prepare(current: MonitorConfig, loops: Sequence[Loop], quota: Quota) -> Reload | Exception:
    """Parse ``current.source`` again and load what changed (any thread); an exception is
    returned, not raised: the running config and model stay."""
    try:
        cfg = load_config(current.source)
        if loop_layout(cfg) != loop_layout(current):
            log.warning("loop changes other than their models take effect at the next restart")
            cfg = replace(cfg, loops=current.loops, model=current.model)
        same_rules = ticker_rules(cfg) == ticker_rules(current)
        loaded: list[tuple[MonitorModel, Ticker, str] | None] = []
        for lc, lp in zip(cfg.monitored_loops, loops, strict=True):
            digest = sha256_file(lc.model)
            if digest == lp.digest and same_rules:
                loaded.append(None)  # the same model, judged the same way: keep its ticker
            else:
                loaded.append((*Loop.load(lc, cfg, lp.view), digest))
        event_log = (
            EventLog(cfg.event_log.path, cfg.event_log.rotate_bytes, quota)
            if cfg.event_log.path != current.event_log.path
            else None
        )
    except Exception as exc:  # any failure: keep monitoring with what we have
        return exc
    return Reload(cfg, loaded, event_log)


def ticker_rules(cfg: MonitorConfig) -> tuple[Any, ...]:
    """The settings a ticker is built with besides its model (the machine declared decides
    whether its model is a reference, ``machinecard.reference_reason``)."""
    return (cfg.alarm, cfg.horizon, cfg.gating, cfg.machine_id)


def loop_layout(cfg: MonitorConfig) -> list[tuple[Any, ...]]:
    """What a reload cannot change: each loop's name, signals, alarm message and address
    (the single loop's address is ``j1939.source_address``, whose changes wait anyway)."""
    return [
        (lc.name, lc.signals, lc.alarm_message, lc.source_address if cfg.loops else None)
        for lc in cfg.monitored_loops
    ]


class Reloader:
    """Runs ``prepare_fn`` on a ``reload`` thread per request; ``poll`` (detector thread)
    hands over a finished result, or an error once a reload has taken too long."""

    def __init__(
        self, prepare_fn: Callable[[], Reload | Exception], limit_s: float | None = None
    ) -> None:
        self._prepare = prepare_fn
        self.limit_s = RELOAD_LIMIT_S if limit_s is None else limit_s
        self._lock = threading.Lock()
        self.busy = False  # a reload thread is parsing (and not given up)
        self._again = False  # another request came meanwhile: run once more after it
        self._gen = 0  # requests started
        self._given_up = 0  # the last one given up as overdue
        self._since = 0.0
        self._result: Reload | Exception | None = None
        self.hung = 0  # reloads given up (their threads may still be stuck)

    @property
    def pending(self) -> bool:
        """Something for ``poll`` to look at (read without the lock: a hint only)."""
        return self.busy or self._result is not None

    def request(self) -> None:
        with self._lock:
            if self.busy:
                self._again = True
                return
            self.busy = True
            self._gen += 1
            self._since = time.monotonic()
            gen = self._gen
        threading.Thread(target=self._run, args=(gen,), name="reload", daemon=True).start()

    def _run(self, gen: int) -> None:
        result = self._prepare()
        with self._lock:
            if gen <= self._given_up:  # given up: ``poll`` already freed the next request
                return
            self._result = result
            self.busy = False
            again, self._again = self._again, False
        if again:
            self.request()

    def poll(self) -> Reload | Exception | None:
        """The finished reload, a ``TimeoutError`` for one given up now, or None."""
        with self._lock:
            result, self._result = self._result, None
            if result is not None:
                return result
            if not self.busy or time.monotonic() - self._since <= self.limit_s:
                return None
            self._given_up = self._gen  # its result, if it ever comes, is dropped
            self.busy = False
            self.hung += 1
            again, self._again = self._again, False
        if again:  # a SIGHUP that came while it hung
            self.request()
        return TimeoutError(
            f"still not parsed after {self.limit_s:g} s; given up ({self.hung} "
            "hung so far), the next SIGHUP reloads again"
        )


def swap_in(
    result: Reload | Exception, running: MonitorConfig, loops: Sequence[Loop], disk: DiskOutputs
) -> MonitorConfig | None:
    """Swap a prepared reload in (detector thread, between two frames): the new config, or
    None when the reload failed (the running config and models stay)."""
    if isinstance(result, Exception):
        log.error("reload failed, keeping the running config and model: %s", result)
        return None
    cfg, loaded, event_log = result
    cfg = _restart_settings_kept(cfg, running)
    disk.reconfigure(cfg, event_log)
    for lp, lc, new in zip(loops, cfg.monitored_loops, loaded, strict=True):
        lp.swap(lc, cfg, new)
        if new is None:
            log.info(
                "reloaded %s: loop %s, model %s unchanged; its J window and alarm state go on",
                cfg.source,
                lp.name,
                lc.model,
            )
        else:
            log.info(
                "reloaded %s: loop %s, model %s (eps0 %.4g); its J window starts "
                "again and the alarm state (%s) holds until it has judged a full "
                "window",
                cfg.source,
                lp.name,
                lc.model,
                new[0].eps0,
                lp.state.label,
            )
    return cfg


def _restart_settings_kept(cfg: MonitorConfig, running: MonitorConfig) -> MonitorConfig:
    """``cfg`` with the running bus, DBC and J1939 settings: their changes wait for a restart."""
    if cfg.bus != running.bus or cfg.dbc != running.dbc:
        log.warning("bus and dbc changes take effect at the next restart")
        cfg = replace(cfg, bus=running.bus, dbc=running.dbc)
    if cfg.j1939 != running.j1939:
        log.warning("j1939 changes take effect at the next restart")
        cfg = replace(cfg, j1939=running.j1939)
    return cfg
