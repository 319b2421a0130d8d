"""The live frame pipeline, free of threads, buses and disks: frames in, decisions out.

One ``feed`` per received frame: J1939 requests go to the loops' diagnostics, the rest is
decoded (alive counter, CRC, ranges), sampled onto the 100 Hz clock and every finished row
ticked by each loop; a loop's state changes and its MON_Alarm / DM1 frames leave through the
two callbacks the daemon gives (``send``, ``on_change``).  ``flush`` ticks the last rows.
The sample clock is the frames' own timestamps, so a log replayed onto a bus gives the
events ``monitor detect`` gives for the file.

Silence is decided from the data, never from a thread that got no CPU for a while:

* any other frame (a foreign ID, a rejected frame) whose timestamp lies ``bus.silent_s``
  past the last sensor frame proves the sensors silent up to it: the clock runs on to it,
  but never further than the reader's own clock saw pass since that sensor frame (a
  sender's timestamps are not trusted beyond the reader's clock);
* with no frame at all, only the reader can prove silence: ``heard_until`` is the start of
  its latest receive that found nothing (every frame that arrived before is queued), and
  ``received_at`` the moment it received its latest frame (stamped by the reader thread at
  receive time, so no later than the last sensor frame's).  When the first lies
  ``bus.silent_s`` past the second, and nothing waits in the queue, the clock runs on by that
  proven time.  Both are the reader's own clock readings: a backlog in the queue, or a
  detector thread starved of CPU, proves nothing and never makes the monitor inactive.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import can
import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.config.layout import rod_columns
from monitor.detection.ticker import Tick
from monitor.io.candump import MAX_TIMESTAMP_S
from monitor.live.loops import Loop
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
    ) -> None:
        self.codec = codec
        self.loops = loops
        # A loop's rod sensor is optional: it never holds the first rows back (warming).
        optional = rod_columns(lp.cfg for lp in loops)
        self.sampler = Sampler.for_codec(codec, columns=columns, optional=optional)
        self._hydraulic = hydraulic_messages(codec, columns)
        self._diags = [lp.diag for lp in loops if lp.diag is not None]  # kept on reload
        self._send = send
        self._on_change = on_change
        self.silent_s = silent_s
        self._scale = time_scale
        self._heard_until = heard_until
        self._backlog = backlog
        self._received_at = received_at  # None: no reader, the pipeline stamps frames itself
        self.last_t_s: float | None = None  # sample-clock time of the last row ticked
        self.bad_timestamps = 0  # frames ignored: a timestamp outside 0..MAX_TIMESTAMP_S
        self._last_ok_mono = time.monotonic()  # wall time of the last sensor frame, no reader
        self._last_ok_ts = 0.0  # its sample-clock time (``_clock``)
        self._last_ok_rx = -float("inf")  # the reader's receive stamp by then (``received_at``)

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
        if self._received_at is None:
            self._last_ok_mono = time.monotonic()
        else:
            self._last_ok_rx = self._received_at()
        self._last_ok_ts = ts
        self._tick_rows(self.sampler.take())

    def silence(self) -> None:
        """No frame waiting: silence the reader has proven runs the clock on."""
        if not self.sampler.started:
            return
        heard = self._heard_until()  # read before the queue: a frame queued later is pending
        if self._backlog():
            return
        # Read after the queue: a frame that came in since is later than ``heard``: no proof.
        last = self._last_ok_mono if self._received_at is None else self._received_at()
        self._run_clock_on((heard - last) / self._scale)

    def _other_frame(self, bus_ts: float) -> None:
        if self.sampler.started and bus_ts == bus_ts:  # NaN stamps prove nothing
            idle = self._clock(bus_ts) - self._last_ok_ts
            if self._received_at is not None:
                # A sender's timestamp proves no more time than the reader's own clock saw
                # pass: a flood stamped ahead must not run the sample clock on.
                idle = min(idle, (self._received_at() - self._last_ok_rx) / self._scale)
            self._run_clock_on(idle)

    def _run_clock_on(self, idle_s: float) -> None:
        """``idle_s`` sample seconds since the last sensor frame are proven silent."""
        if not idle_s >= self.silent_s / self._scale:
            return
        # Past the sampler's max gap the clock stops: the state is inactive by then, and a
        # frame after a longer silence is mapped to the end of that gap (sampler rule).
        idle_s = min(idle_s, self.sampler.max_gap_s - 2 * self.sampler.period_s)
        self._tick_rows(self.sampler.advance(self._last_ok_ts + idle_s))

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

    def _tick_loop(self, lp: Loop, row: np.ndarray, bus_time: float) -> None:
        tick = lp.tick(row)
        if tick.changed:
            self._on_change(tick, lp)
        ticker, frames = lp.ticker, lp.frames
        if frames.due(tick.t_s, tick.state, tick.state_changed):
            self._send(frames.alarm(tick.state, tick.j, ticker.eps0, ticker.fault, bus_time))
        for msg in lp.dm_frames(tick, bus_time, row):
            self._send(msg)
