"""MON_Status, the daemon's heartbeat: every ``outputs.status_period_s`` of wall time, the
most pressing state of the loops and the pump rule (and PumpFault: the pump's, where the
DBC has it), the reader's and decoder's counters, the operating state and the
gating's news (shared by the loops), the bus events and the disk's trouble."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import can

from monitor.bus.reader import BusReader
from monitor.codec.frames import FrameCodec
from monitor.detection.alarm import State
from monitor.live.disk import DiskOutputs
from monitor.live.loops import Loop, worst_state


class Heartbeat:
    def __init__(
        self,
        codec: FrameCodec,
        loops: Sequence[Loop],
        reader: BusReader,
        disk: DiskOutputs,
        send: Callable[[can.Message], None],
        pump: Callable[[], State | None] = lambda: None,
    ) -> None:
        self.codec = codec
        self.pump = pump  # the pump rule's state now (None: no pump rule)
        self.loops = loops
        self.reader = reader
        self.disk = disk
        self.send = send
        self._last_mono = 0.0

    def beat(self, period_s: float) -> None:
        """Send MON_Status if ``period_s`` has passed since the last one."""
        now = time.monotonic()
        if now - self._last_mono < period_s:
            return
        self._last_mono = now
        disk_error = self.disk.trouble(now)
        r, rc = self.reader.counts, self.reader.recovery
        gates = [lp.ticker.gate for lp in self.loops]  # the operating state is shared
        oor, check = any(g.oor >= 0 for g in gates), any(g.check != 0 for g in gates)
        pump = self.pump()
        states = [lp.state for lp in self.loops] + ([pump] if pump is not None else [])
        self.send(
            # Every loop's frames share MON_Status's layout; the first loop's build it.
            self.loops[0].frames.status(
                worst_state(states),
                r.received,
                self.codec.counts.rejected_total,
                r.dropped,
                time.time(),
                int(gates[0].op_state),
                oor,
                check,
                rc.bus_down + rc.bus_off + rc.error_passive,
                disk_error,
                pump is State.FAULT,
            )
        )
