"""The pump rule's tick in the four-loop daemon benchmark (``monitor.bench.live --loops 4``,
config/excavator4.yaml's ``pump:``): the daemon ticks it after the loops in every row
(``MachineWatch.tick``: the rule, MON_Alarm_Pump when due and its DM1), timed apart."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np


class PumpProbe:
    """The timed wrapper of ``MachineWatch.tick`` and what it notes per row: its CPU
    (``time.thread_time``) and the row's latency from the arrival of the frame completing
    it (``current["arrival"]``, the live probe's) to the pump's tick's end."""

    def __init__(self, current: dict[str, Any]) -> None:
        self.current = current
        self.cpu: list[float] = []
        self.latency: list[float] = []

    def timed(self, tick: Callable[..., None]) -> Callable[..., None]:
        current = self.current

        def timed_pump(*args: Any) -> None:
            c0 = time.thread_time()
            tick(*args)
            if current["stopping"]:  # the last row, ticked at shutdown
                return
            self.cpu.append(time.thread_time() - c0)
            self.latency.append(time.perf_counter() - current["arrival"])

        return timed_pump

    def summary(self, loops_cpu_ms: np.ndarray) -> dict[str, Any]:
        """Its CPU per row (us), the row's latency to its end and the row's CPU with it
        (the loops' and the pump's, ms); {} without a pump rule."""
        if not self.cpu:
            return {}
        pump = np.array(self.cpu) * 1e6
        lat = np.array(self.latency) * 1e3
        n = min(pump.size, loops_cpu_ms.size)
        row = loops_cpu_ms[:n] + pump[:n] * 1e-3
        return {
            "pump_ticks": int(pump.size),
            "pump_tick_cpu_median_us": float(np.median(pump)),
            "pump_tick_cpu_p99_us": float(np.percentile(pump, 99)),
            "pump_share_of_row_cpu_median": float(np.median(pump[:n] * 1e-3 / row)),
            "row_with_pump_p50_ms": float(np.percentile(lat, 50)),
            "row_with_pump_p99_ms": float(np.percentile(lat, 99)),
            "row_cpu_with_pump_median_ms": float(np.median(row)),
            "row_cpu_with_pump_p99_ms": float(np.percentile(row, 99)),
        }
