"""The live frame pipeline, free of threads, buses and disks: frames in, decisions out.

One ``feed`` per received frame: J1939 requests go to the loops' diagnostics, the rest is
decoded (alive counter, CRC, ranges), sampled onto the 100 Hz clock and every finished row
ticked by each loop; a loop's state changes and its MON_Alarm / DM1 frames leave through the
two callbacks the daemon gives (``send``, ``on_change``, which also hears an alarm a
reference model withheld).  ``flush`` ticks the last rows.
The sample clock is the frames' own timestamps, so a log replayed onto a bus gives the
events ``monitor detect`` gives for the file.

Silence is decided from the data, never from a thread that got no CPU for a while
(``monitor.live.silence``).  ``send`` and ``on_change`` are the pipeline's outputs, called
for every frame and state change (the live benchmark times them there).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import can
import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.config.layout import rod_columns
from monitor.detection.machine import Alarm
from monitor.detection.ticker import Tick
from monitor.io.candump import MAX_TIMESTAMP_S
from monitor.live.loops import Loop
from monitor.live.machine import MachineWatch, Say
from monitor.live.silence import SilenceProof
from monitor.sampling.sampler import Sampler, hydraulic_messages

log = logging.getLogger("monitor")

Send = Callable[[can.Message], None]
OnChange = Callable[[Tick, Loop], None]


class FramePipeline:
    def __init__(
        self,
        codec: FrameCodec,
        columns: tuple[str, ...],
        loops: list[Loop],
        send: Send,
        on_change: OnChange,
        silent_s: float = 0.5,
        time_scale: float = 1.0,
        heard_until: Callable[[], float] = time.monotonic,
        backlog: Callable[[], bool] = lambda: False,
        received_at: Callable[[], float] | None = None,
        machine: MachineWatch | None = None,
        say: Say = lambda _ev: None,
    ) -> None:
        self.codec = codec
        self.loops = loops
        self.machine = machine  # the pump rule and the machine's finding (several loops)
        self.say = say  # their event lines
        # A loop's rod sensor is optional: it never holds the first rows back (warming).
        optional = rod_columns(lp.cfg for lp in loops)
        self.sampler = Sampler.for_codec(codec, columns=columns, optional=optional)
        self._hydraulic = hydraulic_messages(codec, columns)
        self._diags = [lp.diag for lp in loops if lp.diag is not None]  # kept on reload
        if machine is not None and machine.diag is not None:
            self._diags.append(machine.diag)  # the pump's DM1/DM2 answers requests too
        self.send = send
        self.on_change = on_change
        self._scale = time_scale
        self.proof = SilenceProof(silent_s, time_scale, heard_until, backlog, received_at)
        self.last_t_s: float | None = None  # sample-clock time of the last row ticked
        self.bad_timestamps = 0  # frames ignored: a timestamp outside 0..MAX_TIMESTAMP_S

    @property
    def start_time_s(self) -> float | None:
        """Log time of row t = 0: the first sensor frame's, plus the warming rows."""
        return self.sampler.start_time_s

    def feed(self, msg: can.Message) -> None:
        """One received frame (the black box has already seen it)."""
        # The bound a candump line's timestamp has offline; NaN fails too: no time, no sample.
        if not 0.0 <= msg.timestamp <= MAX_TIMESTAMP_S:
            self.bad_timestamps += 1
            return
        # A request to all (DA 255) is for every loop's address: no short cut.
        if self._diags and sum([diag.request(msg) for diag in self._diags]):
            return  # a J1939 request for DM1/DM2: answered at the next tick
        d = self.codec.decode_message(msg)
        if d.rejection is not None or d.name not in self._hydraulic:
            if d.rejection is not None:
                log.debug("rejected frame %X: %s", msg.arbitration_id, d.rejection.value)
            self._other_frame(msg.timestamp)  # not a sensor frame, but proof of time
            return
        ts = self._clock(msg.timestamp)
        self.sampler.feed(ts, d.name, d.values)  # type: ignore[arg-type]
        self.proof.sensor_frame(ts)
        self._tick_rows(self.sampler.take())

    def silence(self) -> None:
        """No frame waiting: silence the reader has proven runs the clock on."""
        if self.sampler.started:
            self._run_clock_on(self.proof.idle_heard())

    def _other_frame(self, bus_ts: float) -> None:
        if self.sampler.started and bus_ts == bus_ts:  # NaN stamps prove nothing
            self._run_clock_on(self.proof.idle_before(self._clock(bus_ts)))

    def _run_clock_on(self, idle_s: float) -> None:
        """``idle_s`` sample seconds since the last sensor frame are proven silent."""
        if not self.proof.silent(idle_s):
            return
        # Past the sampler's max gap the clock stops: the state is inactive by then, and a
        # frame after a longer silence is mapped to the end of that gap (sampler rule).
        idle_s = min(idle_s, self.sampler.max_gap_s - 2 * self.sampler.period_s)
        self._tick_rows(self.sampler.advance(self.proof.last_ok_ts + idle_s))

    def flush(self) -> None:
        """The rows up to the instant of the last frame, as ``monitor detect`` has them."""
        self._tick_rows(self.sampler.flush())

    def bus_time(self, t_s: float) -> float:
        """Bus time of a row's time ``t_s`` (row t = 0 is the first row past warming)."""
        origin_s = self.sampler.origin_k * self.sampler.period_s
        return (self.sampler.first_time_s or 0.0) + (origin_s + t_s) * self._scale

    def _clock(self, bus_ts: float) -> float:
        """Sample-clock time of a bus timestamp (the first sensor frame is the origin)."""
        t0 = self.sampler.first_time_s
        if t0 is None or self._scale == 1.0:
            return bus_ts  # exactly the bus time: same rows as ``monitor detect`` of a log
        return t0 + (bus_ts - t0) / self._scale

    def _tick_rows(self, rows: np.ndarray) -> None:
        if len(rows):
            self.last_t_s = float(rows[-1, 0])
        for row in rows:
            bus_time = self.bus_time(float(row[0]))
            for lp in self.loops:
                self._tick_loop(lp, row, bus_time)
            if self.machine is not None:
                self.machine.tick(row, bus_time, self.start_time_s, self.send, self.say)

    def _finding(self, lp: Loop, tick: Tick) -> None:
        """A loop's alarm raised or its episode over, to the machine's finding."""
        assert self.machine is not None
        if tick.raised:
            alarm = Alarm(lp.name, tick.t_s, tick.level)
            self.machine.raised(alarm, self.start_time_s, self.say)
        elif not tick.episode_open:
            self.machine.cleared(lp.name, tick.t_s, self.start_time_s, self.say)

    def _tick_loop(self, lp: Loop, row: np.ndarray, bus_time: float) -> None:
        tick = lp.tick(row)
        if tick.changed or tick.withheld:  # a withheld alarm is said, never raised
            self.on_change(tick, lp)
            if self.machine is not None:
                self._finding(lp, tick)
        ticker, frames = lp.ticker, lp.frames
        if frames.due(tick.t_s, tick.state, tick.state_changed):
            self.send(frames.alarm(tick.state, tick.j, ticker.eps0, ticker.fault, bus_time))
        for msg in lp.dm_frames(tick, bus_time, row):
            self.send(msg)
