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

The daemon composes its parts, each with one job: the reader (``monitor.bus.reader``), the
frame pipeline (frames in, decisions out: ``monitor.live.pipeline``), the monitored loops
(``monitor.live.loops``; ``loops[0]`` is the only one without ``loops:`` in the config), the
disk outputs (``monitor.live.disk``), the transmitter every own frame leaves through
(``monitor.live.transmit``), the MON_Status heartbeat (``monitor.live.status``), the
detector thread (``monitor.live.detector``) and the reload (``monitor.live.reload``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from functools import partial
from typing import Any

import can

from monitor.bus.reader import BusReader, CanBus, open_bus
from monitor.bus.recovery import Backoff
from monitor.codec.frames import FrameCodec
from monitor.config.layout import row_layout
from monitor.config.settings import MonitorConfig
from monitor.detection.alarm import State
from monitor.detection.ticker import Tick
from monitor.live.detector import DetectorThread
from monitor.live.disk import DiskOutputs
from monitor.live.dm1 import Diagnostics
from monitor.live.eventlog import bus_event_record
from monitor.live.loops import Loop, worst_state
from monitor.live.machine import MachineWatch
from monitor.live.pipeline import FramePipeline
from monitor.live.reload import Reload, Reloader, prepare, swap_in
from monitor.live.status import Heartbeat
from monitor.live.transmit import Transmitter
from monitor.sampling.sampler import sensor_filters

log = logging.getLogger("monitor")

EventHook = Callable[[dict[str, Any]], None]


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
        # Several loops: the pump rule (``pump:``) and the machine's finding over them.
        self.machine = MachineWatch(cfg, self.codec, self.columns) if cfg.loops else None
        self.disk = DiskOutputs(cfg)  # its writer thread runs from here on
        self.reader = _reader(cfg, self.codec, self.columns, bus, opener)
        self.tx = Transmitter(self.reader, cfg.outputs.frames_max_per_s, cfg.bus.time_scale)
        self.pipeline = FramePipeline(
            self.codec,
            self.columns,
            self.loops,
            self.tx.send,
            self._state_change,
            cfg.bus.silent_s,
            cfg.bus.time_scale,
            lambda: self.reader.heard_until,
            lambda: not self.reader.queue.empty(),
            lambda: self.reader.received_at,
            self.machine,
            self._machine_event,
        )
        machine = self.machine
        self.heartbeat = Heartbeat(
            self.codec,
            self.loops,
            self.reader,
            self.disk,
            self.tx.send,
            (lambda: machine.state) if machine is not None else (lambda: None),
        )
        self.reloader = Reloader(lambda: prepare(self.cfg, self.loops, self.disk.quota))
        self.reloads = 0  # reloads swapped in
        self.reload_attempts = 0  # reloads finished, successful or not
        self.detector = DetectorThread(self.reader.queue, self)

    # -- control (any thread) -------------------------------------------------------------

    def start(self) -> None:
        self.detector.start()
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

    def reload_now(self) -> None:
        """Reload at once in this thread (parse, load, swap): what a SIGHUP does in two."""
        self._apply_reload(prepare(self.cfg, self.loops, self.disk.quota))

    @property
    def healthy(self) -> bool:
        return self.error is None and self.detector.alive and self.reader.alive

    @property
    def error(self) -> BaseException | None:
        """What ended the detector thread, if anything did."""
        return self.detector.error

    @property
    def loop_mono(self) -> float:
        """Monotonic time of the detector loop's last pass (the watchdog's)."""
        return self.detector.loop_mono

    @property
    def state(self) -> State:
        """The most pressing loop's state (fault, sensor fault, normal, inactive)."""
        return worst_state([lp.state for lp in self.loops])

    @property
    def unwritten(self) -> int:
        """Events still not on disk when ``stop`` returned."""
        return self.disk.unwritten

    def stop(self, timeout_s: float = 10.0) -> None:
        """Ordered shutdown; safe to call twice."""
        self.reader.stop()
        self.detector.stop(timeout_s)
        self.disk.close(timeout_s)
        if self.reader.opener is not None:  # a bus of our own (one given is the caller's)
            self.reader.bus.shutdown()
        log.info("stopped: %s", self.counts())

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
            **self.pipeline.sampler.counts.as_dict(),
            "ticks": sum(lp.ticker.ticks for lp in self.loops),
            "alarm_frames": sum(lp.frames.sent for lp in self.loops),
            "alarm_frames_held_back": sum(lp.frames.held_back for lp in self.loops),
            "events": self.disk.event_log.written,
            "disk_errors": self.disk.disk_errors,
            "events_unwritten": self.disk.event_log.unwritten,
            "tx_errors": self.tx.errors,
            "tx_capped": self.tx.capped,
            "bad_timestamps": self.pipeline.bad_timestamps,
            **(self.machine.counts if self.machine is not None else {}),
            **diag,
            "error_frames": r.error_frames,
            **self.reader.recovery.as_dict(),
        }

    # -- detector thread (monitor.live.detector) ------------------------------------------

    def reload_point(self) -> None:
        """Between two frames: swap in a reload that finished."""
        if self.reloader.pending:
            result = self.reloader.poll()
            if result is not None:
                self._apply_reload(result)

    def frame(self, msg: can.Message) -> None:
        """One received frame: to the black box, then through the pipeline."""
        if not self.reader.events.empty():  # a bus event before this frame is logged first
            self.bus_events()
        self.disk.black_box.add(msg)
        self.pipeline.feed(msg)

    def idle(self) -> None:
        """No frame for a while: silence the reader has proven runs the clock on."""
        self.pipeline.silence()

    def beat(self) -> None:
        self.heartbeat.beat(self.cfg.outputs.status_period_s)

    def finish(self) -> None:
        self.pipeline.flush()  # the instant of the last frame, as offline
        self.bus_events()

    def bus_events(self) -> None:
        """The reader's bus events to the event log, with the most pressing loop's state."""
        events = self.reader.take_events()
        if not events:
            return
        state = self.state
        lp = next(lp for lp in self.loops if lp.state is state)  # the loop the state is of
        for ev in events:
            self.disk.log_event(
                bus_event_record(
                    ev, self.pipeline.last_t_s, state, lp.last_j, lp.ticker.eps0, lp.ticker.fault
                )
                | lp.tag
            )

    def _state_change(self, tick: Tick, lp: Loop) -> None:
        if tick.withheld:  # a reference model's alarm: a line and the journal, nothing raised
            line = lp.withheld_event(tick, self.pipeline.start_time_s)
            self.disk.log_event(line)
            log.warning("t=%.2f s: %salarm withheld: %s", line["t"], _prefix(lp), line["reason"])
            if self.on_event is not None:
                self.on_event(line)
        if not tick.changed:
            return
        ev = lp.event(tick, self.pipeline.start_time_s)
        self.disk.log_event(ev)
        _log_change(tick, lp, ev)
        if tick.raised:  # a new episode; a fault back after a short gap is the same one
            self.disk.black_box.trigger(
                self.pipeline.bus_time(tick.t_s), lp.alarm_label(), ev["seq"]
            )
        if self.on_event is not None:
            self.on_event(ev)

    def _machine_event(self, ev: dict[str, Any]) -> None:
        """The pump rule's state change or the machine's finding: the event log, the
        journal (a warning for a pump fault and a finding naming something)."""
        self.disk.log_event(ev)
        if ev.get("kind") == "finding":
            level = logging.WARNING if ev["named"] else logging.INFO
            log.log(
                level,
                "t=%.2f s: machine finding: %s%s%s",
                ev["t"],
                ev["named"] or "none",
                f", explained by the pump: {', '.join(ev['explained_by_pump'])}"
                if ev["explained_by_pump"]
                else "",
                f", secondary: {', '.join(ev['secondary'])}" if ev["secondary"] else "",
            )
        else:
            level = logging.WARNING if ev["state"] == "fault" else logging.INFO
            log.log(
                level,
                "t=%.2f s: pump: %s (margin residual %s bar, threshold %s bar)",
                ev["t"],
                ev["state"],
                ev["margin_residual_bar"],
                ev["threshold_bar"],
            )
        if self.on_event is not None:
            self.on_event(ev)

    def _apply_reload(self, result: Reload | Exception) -> None:
        self.reload_attempts += 1
        cfg = swap_in(result, self.cfg, self.loops, self.disk)
        if cfg is not None:
            self.cfg = cfg
            self.reloads += 1


def _reader(
    cfg: MonitorConfig,
    codec: FrameCodec,
    columns: tuple[str, ...],
    bus: CanBus | None,
    opener: Callable[[], can.BusABC] | None,
) -> BusReader:
    """The reader on ``bus``, or on a bus of its own that it reopens after a failure."""
    if opener is None:
        extra = Diagnostics.rx_filters() if cfg.j1939.enabled else []
        opener = partial(open_bus, cfg.bus, sensor_filters(codec, columns) + extra)
    return BusReader(
        bus if bus is not None else opener(),
        cfg.bus.queue_frames,
        opener=opener if bus is None else None,
        backoff=Backoff(cfg.bus.reopen_initial_s, cfg.bus.reopen_max_s),
    )


def _prefix(lp: Loop) -> str:
    return f"{lp.name}: " if lp.tag else ""


def _log_change(tick: Tick, lp: Loop, ev: dict[str, Any]) -> None:
    """A state change to the journal (a warning unless normal), and the gating's news."""
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
