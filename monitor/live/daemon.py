"""The live monitor: bus -> decoder -> sampler -> ticker -> outputs, on its own threads.

Threads: ``can-reader`` (``BusReader``: bus -> bounded queue, nothing else) and ``detector``
(everything else, in arrival order: black box, decode, sampler, one tick per 100 Hz row and
loop, frames, disk jobs).  Several loops (``loops:`` in the config, ``monitor.live.loops``) share
the reader, the decoder and one sampler row; each ticks its own model on it and sends its
own MON_Alarm and DM1; MON_Status shows the most pressing loop.  Nothing runs in a
python-can Notifier callback.  The sample clock is the frames' own timestamps, so a log
replayed onto a bus gives the events ``monitor detect`` gives for the file.  When no sensor
frame is accepted for ``bus.silent_s`` (wall clock) the clock runs on by wall time: the rows
go stale, the engine speed with them, and the monitor is inactive (a machine that is off is
not faulty); when frames return, it resumes.  With ``bus.time_scale`` k the sample clock runs
k times slower than the frames' timestamps (a log replayed k times slower than real time
keeps its own timing).  A bus that fails (link down, bus-off) is reopened by the reader with
backoff while the detector goes on (its silence is such a gap); bus events go to the event
log as ``kind: "bus"`` lines (monitor/bus_recovery.py), and nothing is sent while the bus is
down (counted as tx errors).

``stop()`` shuts down in order: reader (no new frames), detector (drains the queue, ticks
the last rows), disk writer (drains its queue: events fsynced, black box and event log
closed), bus.  ``request_reload`` makes the detector thread reload config and model between
two frames, keeping the bus.  Disk jobs (event log, black-box files) go to the
``disk-writer`` thread through a bounded queue (``monitor.live.writer``): no fsync or black-box
dump stalls a tick.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import Any

import can

from monitor.bus.reader import BusReader, CanBus, open_bus
from monitor.bus.recovery import Backoff
from monitor.codec.frames import FrameCodec
from monitor.config.layout import row_layout
from monitor.config.settings import MonitorConfig
from monitor.detection.alarm import State
from monitor.detection.ticker import Tick, Ticker
from monitor.live.blackbox import BlackBox
from monitor.live.dm1 import Diagnostics
from monitor.live.eventlog import bus_event_record
from monitor.live.loops import Loop, worst_state
from monitor.live.outputs import AlarmFrames, EventLog
from monitor.live.pipeline import FramePipeline
from monitor.live.ratecap import RateCap
from monitor.live.reload import Reload, Reloader, prepare
from monitor.live.storage import Quota
from monitor.live.writer import DiskWriter
from monitor.model.modelfile import MonitorModel
from monitor.sampling.sampler import Sampler, sensor_filters

log = logging.getLogger("monitor")

EventHook = Callable[[dict[str, Any]], None]
_RETRY_S = 5.0  # how often events the disk refused are tried again


class Daemon:
    def __init__(
        self,
        cfg: MonitorConfig,
        bus: CanBus | None = None,
        on_event: EventHook | None = None,
        opener: Callable[[], can.BusABC] | None = None,
    ) -> None:
        """``bus`` (optional) is used instead of opening ``cfg.bus``; it is not shut down or
        reopened.  ``opener`` (optional) opens the bus instead of ``cfg.bus``, at the start
        and again after a failure."""
        self.cfg = cfg
        self.on_event = on_event
        self.codec = FrameCodec.from_dbc(cfg.dbc)
        self.columns, views = row_layout(cfg, self.codec)
        self.loops = [
            Loop(lc, cfg, self.codec, v) for lc, v in zip(cfg.monitored_loops, views, strict=True)
        ]
        # Disk I/O (event log, black box) runs in the disk writer's thread; see monitor.live.writer.
        st = cfg.storage
        self.quota = Quota(st.quota_bytes, cfg.black_box.directory, cfg.event_log.path)
        self.event_log = EventLog(cfg.event_log.path, cfg.event_log.rotate_bytes, self.quota)
        self.writer = DiskWriter(st.writer_queue, st.event_block_s)
        self.black_box = BlackBox(cfg.black_box, cfg.bus.channel, self.writer, self.quota)
        self.writer.start()
        self._own_bus = bus is None
        if opener is None:
            extra = Diagnostics.rx_filters() if cfg.j1939.enabled else []
            opener = partial(open_bus, cfg.bus, sensor_filters(self.codec, self.columns) + extra)
        backoff = Backoff(cfg.bus.reopen_initial_s, cfg.bus.reopen_max_s)
        self.reader = BusReader(
            bus if bus is not None else opener(),
            cfg.bus.queue_frames,
            opener=opener if self._own_bus else None,
            backoff=backoff,
        )
        self.pipeline = FramePipeline(
            self.codec,
            self.columns,
            self.loops,
            self._send,
            self._state_change,
            cfg.bus.silent_s,
            cfg.bus.time_scale,
            lambda: self.reader.heard_until,
            lambda: not self.reader.queue.empty(),
            lambda: self.reader.received_at,
        )
        self.tx_errors = 0
        self.tx_capped = 0  # own frames dropped by outputs.frames_max_per_s
        self._last_cap_log = 0.0
        # A log replayed faster than real time (time_scale < 1) times its alarms faster too.
        self._budget = RateCap(cfg.outputs.frames_max_per_s / min(1.0, cfg.bus.time_scale))
        self.unwritten = 0  # events still not on disk when ``stop`` returned
        self._disk_errors_sent = 0  # disk_errors at the last MON_Status
        self._last_retry_mono = 0.0
        self.reloads = 0
        self.loop_mono = time.monotonic()  # last pass of the detector loop (watchdog)
        self.reload_attempts = 0  # reloads finished, successful or not
        self._last_status_mono = 0.0
        self._last_tx_error_log = 0.0
        self._stop = threading.Event()
        self.reloader = Reloader(lambda: prepare(self.cfg, self.loops, self.quota))
        self._thread = threading.Thread(target=self._run, name="detector", daemon=True)
        self.error: BaseException | None = None

    # -- control (any thread) -------------------------------------------------------------

    def start(self) -> None:
        self._thread.start()
        self.reader.start()
        for lp in self.loops:
            log.info(
                "monitoring %s:%s, loop %s: model %s (eps0 %.4g, window %d)",
                self.cfg.bus.interface,
                self.cfg.bus.channel,
                lp.name,
                lp.cfg.model,
                lp.model.eps0,
                lp.model.window_n,
            )

    def request_reload(self) -> None:
        """SIGHUP: parse and load on a thread of its own (``monitor.live.reload``); the
        detector swaps the result in between two frames."""
        self.reloader.request()

    @property
    def healthy(self) -> bool:
        return self.error is None and self._thread.is_alive() and self.reader.alive

    @property
    def state(self) -> State:
        """The most pressing loop's state (fault, sensor fault, normal, inactive)."""
        return worst_state([lp.state for lp in self.loops])

    # The first loop's parts (the only loop's, without ``loops:`` in the config).
    @property
    def ticker(self) -> Ticker:
        return self.loops[0].ticker

    @property
    def model(self) -> MonitorModel:
        return self.loops[0].model

    @property
    def frames(self) -> AlarmFrames:
        return self.loops[0].frames

    @property
    def diag(self) -> Diagnostics | None:
        return self.loops[0].diag

    @property
    def last_j(self) -> float:
        return self.loops[0].last_j

    @property
    def last_level(self) -> float:
        """The first loop's alarm level max(J / eps0, B / b0) at its last tick (1 = alarm)."""
        return self.loops[0].last_level

    @property
    def sampler(self) -> Sampler:
        return self.pipeline.sampler

    @property
    def last_t_s(self) -> float | None:
        """Sample-clock time of the last row ticked."""
        return self.pipeline.last_t_s

    @property
    def bus(self) -> CanBus:
        """The bus in use (the reader replaces it when it reopens a failed one)."""
        return self.reader.bus

    def stop(self, timeout_s: float = 10.0) -> None:
        """Ordered shutdown; safe to call twice."""
        self.reader.stop()
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)
        self.black_box.close()  # queues the last post-alarm frames and the file's close
        self.writer.put_event(self.event_log.close)
        self.writer.stop(timeout_s)  # drained: every event written and fsynced, files closed
        if self.writer.counts.frames_dropped or self.writer.counts.events_over_bound:
            log.warning("disk writer: %s", self.writer.counts.as_dict())
        self.unwritten = self.event_log.unwritten + self.event_log.lost + self.writer.pending()
        if self._own_bus:
            self.bus.shutdown()
        log.info("stopped: %s", self.counts())

    @property
    def disk_errors(self) -> int:
        """Failed writes, rotations and deletions of the event log and black boxes."""
        return self.event_log.disk_errors + self.writer.counts.job_errors

    def counts(self) -> dict[str, Any]:
        r = self.reader.counts
        diag: dict[str, int] = {}
        for lp in self.loops:  # summed over the loops
            for k, v in (lp.diag.counts() if lp.diag is not None else {}).items():
                diag[k] = diag.get(k, 0) + v
        return {
            "received": r.received,
            "dropped": r.dropped,
            "bus_errors": r.bus_errors,
            **self.codec.counts.as_dict(),
            **self.sampler.counts.as_dict(),
            "ticks": sum(lp.ticker.ticks for lp in self.loops),
            "alarm_frames": sum(lp.frames.sent for lp in self.loops),
            "alarm_frames_held_back": sum(lp.frames.held_back for lp in self.loops),
            "events": self.event_log.written,
            "disk_errors": self.disk_errors,
            "events_unwritten": self.event_log.unwritten,
            "tx_errors": self.tx_errors,
            "tx_capped": self.tx_capped,
            "bad_timestamps": self.pipeline.bad_timestamps,
            **diag,
            "error_frames": r.error_frames,
            **self.reader.recovery.as_dict(),
        }

    # -- detector thread ------------------------------------------------------------------

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # surfaced by ``healthy``; the supervisor exits
            self.error = exc
            log.exception("detector thread failed")

    def _loop(self) -> None:
        q = self.reader.queue
        while True:
            self.loop_mono = time.monotonic()
            if self.reloader.pending:
                result = self.reloader.poll()
                if result is not None:
                    self._apply_reload(result)
            try:
                msg = q.get(timeout=0.05)
            except queue.Empty:
                if self._stop.is_set():
                    break  # the reader is stopped first, so the queue is drained
                self.pipeline.silence()
            else:
                self._frame(msg)
                for _ in range(1000):  # drain a burst without a timeout per frame
                    try:
                        self._frame(q.get_nowait())
                    except queue.Empty:
                        break
                    # A backlog (slow CPU, a flood) must not stall the heartbeat or make
                    # the watchdog think the loop is stuck.
                    self._status()
                    self.loop_mono = time.monotonic()
            self._status()
            self._bus_events()
        self.pipeline.flush()  # the instant of the last frame, as offline
        self._bus_events()

    def _frame(self, msg: can.Message) -> None:
        if not self.reader.events.empty():  # a bus event before this frame is logged first
            self._bus_events()
        self.black_box.add(msg)
        self.pipeline.feed(msg)

    def _state_change(self, tick: Tick, lp: Loop) -> None:
        ev = lp.event(tick, self.pipeline.start_time_s)
        self._log_event(ev)
        level = logging.WARNING if tick.state is not State.NORMAL else logging.INFO
        log.log(
            level,
            "t=%.2f s: %s%s (J %s, eps0 %.4g%s)",
            ev["t"],
            f"{lp.name}: " if lp.tag else "",
            ev["state"],
            "n/a" if ev["J"] is None else f"{ev['J']:.4g}",
            ev["threshold"],
            f", fault {ev['fault']}" if ev["fault"] else "",
        )
        if tick.op_state or tick.out_of_range or tick.check:  # gating news (detection.gating)
            log.info(
                "t=%.2f s: operating state %s, out of range: %s, sensor check: %s %s",
                ev["t"],
                ev["op_state"],
                ev["out_of_range_signal"],
                ev["sensor"],
                ev["sensor_check"],
            )
        if tick.raised:  # a new episode; a fault back after a short gap is the same one
            self.black_box.trigger(self.pipeline.bus_time(tick.t_s), lp.alarm_label(), ev["seq"])
        if self.on_event is not None:
            self.on_event(ev)

    def _send(self, msg: can.Message) -> None:
        if not self.reader.bus_up:  # down or bus-off: it would fail, or block for nothing
            self.tx_errors += 1
            return
        if not self._budget.take(time.monotonic()):  # whatever the input, never a flood
            self.tx_capped += 1
            now = time.monotonic()
            if now - self._last_cap_log > 5.0:
                self._last_cap_log = now
                log.error(
                    "own frames over outputs.frames_max_per_s (%g/s): %d dropped so far",
                    self.cfg.outputs.frames_max_per_s,
                    self.tx_capped,
                )
            return
        try:
            self.bus.send(msg, timeout=0.05)
        except (can.CanError, OSError) as exc:
            self.tx_errors += 1
            self.reader.report_send_error(exc)  # perhaps the only sign the link went down
            now = time.monotonic()
            if now - self._last_tx_error_log > 5.0:
                self._last_tx_error_log = now
                log.error(
                    "cannot send %X (%s); %d send errors", msg.arbitration_id, exc, self.tx_errors
                )

    def _status(self) -> None:
        now = time.monotonic()
        if now - self._last_status_mono < self.cfg.outputs.status_period_s:
            return
        self._last_status_mono = now
        waiting = self.event_log.unwritten
        if waiting and now - self._last_retry_mono >= _RETRY_S:  # the disk may be back
            self._last_retry_mono = now
            self.writer.put_event(self.event_log.retry)
        errors = self.disk_errors
        disk_error = bool(waiting) or errors != self._disk_errors_sent
        self._disk_errors_sent = errors
        r = self.reader.counts
        rejected = self.codec.counts.rejected_total
        gates = [lp.ticker.gate for lp in self.loops]  # the operating state is shared
        oor, check = any(g.oor >= 0 for g in gates), any(g.check != 0 for g in gates)
        rc = self.reader.recovery
        self._send(
            self.frames.status(
                self.state,
                r.received,
                rejected,
                r.dropped,
                time.time(),
                int(gates[0].op_state),
                oor,
                check,
                rc.bus_down + rc.bus_off + rc.error_passive,
                disk_error,
            )
        )

    def _bus_events(self) -> None:
        events = self.reader.take_events()
        if not events:
            return
        state = self.state
        lp = next(lp for lp in self.loops if lp.state is state)  # the loop the state is of
        for ev in events:
            self._log_event(
                bus_event_record(
                    ev, self.last_t_s, state, lp.last_j, lp.ticker.eps0, lp.ticker.fault
                )
                | lp.tag
            )

    def _log_event(self, ev: dict[str, Any]) -> None:
        """Queue an event-log line for the disk writer (which writes and fsyncs it)."""
        ev["mono"] = round(time.monotonic(), 6)  # this host's monotonic clock, s
        self.event_log.stamp(ev)
        self.writer.put_event(partial(self.event_log.write, ev))

    def _do_reload(self) -> None:
        """Reload at once in this thread (parse, load, swap): what a SIGHUP does in two."""
        self._apply_reload(prepare(self.cfg, self.loops, self.quota))

    def _apply_reload(self, result: Reload | Exception) -> None:
        """Swap a prepared reload in (detector thread, between two frames)."""
        self.reload_attempts += 1
        if isinstance(result, Exception):
            log.error("reload failed, keeping the running config and model: %s", result)
            return
        cfg, loaded, event_log = result
        if cfg.bus != self.cfg.bus or cfg.dbc != self.cfg.dbc:
            log.warning("bus and dbc changes take effect at the next restart")
            cfg = replace(cfg, bus=self.cfg.bus, dbc=self.cfg.dbc)
        if cfg.j1939 != self.cfg.j1939:
            log.warning("j1939 changes take effect at the next restart")
            cfg = replace(cfg, j1939=self.cfg.j1939)
        if event_log is not None:
            self.writer.put_event(self.event_log.close)  # after its queued writes
            self.quota.event_log_path = event_log.path
            self.event_log = event_log
        self.black_box.cfg = cfg.black_box
        self.quota.quota_bytes = cfg.storage.quota_bytes
        for lp, lc, new in zip(self.loops, cfg.monitored_loops, loaded, strict=True):
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
        self.cfg = cfg
        self.reloads += 1
