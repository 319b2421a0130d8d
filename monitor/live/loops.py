"""Several loops in one daemon: one ``Loop`` per loop (model, ticker, MON_Alarm frames, J1939
diagnostics) on its view of the one sampler row (``monitor.config.layout``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import can
import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.config.layout import check_loop_model
from monitor.config.loops import LoopConfig
from monitor.config.settings import MonitorConfig
from monitor.detection.alarm import State
from monitor.detection.plausibility import finding
from monitor.detection.ticker import Tick, Ticker, event, withheld_event
from monitor.io.digest import sha256_file
from monitor.live.dm1 import Diagnostics
from monitor.live.outputs import AlarmFrames
from monitor.model.machinecard import COMMISSION, reference_reason
from monitor.model.modelfile import MonitorModel, load_model
from monitor.signals import source_signal

log = logging.getLogger("monitor")

# MON_Status shows the most pressing loop: a fault before a sensor fault before normal.
_SEVERITY = {State.FAULT: 3, State.SENSOR_FAULT: 2, State.NORMAL: 1, State.INACTIVE: 0}


def worst_state(states: Sequence[State]) -> State:
    return max(states, key=_SEVERITY.__getitem__)


class Loop:
    """One monitored loop: its model and ticker on its view of the row, its MON_Alarm
    frames and (with J1939 on) its DM1/DM2 at its own source address."""

    def __init__(
        self, lc: LoopConfig, cfg: MonitorConfig, codec: FrameCodec, view: tuple[str, ...]
    ) -> None:
        self.cfg = lc
        self.name = lc.name
        self.view = view
        self.model, self.ticker = self.load(lc, cfg, view)
        self.digest = sha256_file(lc.model)  # a reload keeps the ticker if this is unchanged
        self.frames = AlarmFrames(codec, cfg.outputs, lc.alarm_message)
        self.diag: Diagnostics | None = None
        if cfg.j1939.enabled:
            j1939 = replace(cfg.j1939, source_address=lc.source_address)
            signals = tuple(map(source_signal, self.model.spec.variables))
            self.diag = Diagnostics(j1939, signals, view)
        self.tag = {"loop": lc.name} if cfg.loops else {}  # events name the loop when loops are set
        self.last_j = float("nan")
        self.last_level = float("nan")  # max(J / eps0, B / b0) of the last tick, 1 = alarm

    @staticmethod
    def load(
        lc: LoopConfig, cfg: MonitorConfig, view: tuple[str, ...]
    ) -> tuple[MonitorModel, Ticker]:
        """The loop's model and a fresh ticker (raises on a bad model file, or one of
        another loop or machine).  A model not commissioned on the config's ``machine_id``
        withholds its hydraulic alarms (``machinecard.reference_reason``, as ``monitor
        detect``): MON_Alarm stays normal, no DM1, no black box, a ``withheld`` line."""
        model = load_model(lc.model)
        check_loop_model(model, lc, cfg)
        reference = reference_reason(model.card, cfg.machine_id)
        if reference is not None:
            log.warning("loop %s: %s; %s", lc.name, reference, COMMISSION)
        ticker = Ticker(
            model, cfg.alarm, cfg.horizon, columns=view, gating=cfg.gating, reference=reference
        )
        return model, ticker

    def swap(
        self,
        lc: LoopConfig,
        cfg: MonitorConfig,
        new: tuple[MonitorModel, Ticker, str] | None = None,
    ) -> None:
        """A reload: ``new`` (model, ticker, model file digest) takes over from the running
        ticker's alarm state (``Ticker.carry_over``); None keeps model and ticker.  Frames
        and DTC history go on."""
        self.cfg = lc
        self.frames.cfg = cfg.outputs
        if new is not None:
            model, ticker, self.digest = new
            ticker.carry_over(self.ticker)
            self.model, self.ticker = model, ticker

    @property
    def state(self) -> State:
        return self.ticker.state

    def tick(self, row: np.ndarray) -> Tick:
        tick = self.ticker.tick(row)
        self.last_j, self.last_level = tick.j, tick.level
        return tick

    def event(self, tick: Tick, start_time_s: float | None) -> dict[str, Any]:
        return event(tick, self.ticker.fault, self.ticker.eps0, start_time_s) | self.tag

    def withheld_event(self, tick: Tick, start_time_s: float | None) -> dict[str, Any]:
        """The line of an alarm withheld at ``tick`` (a model of another machine)."""
        reason = self.ticker.reference or ""
        return withheld_event(tick, reason, start_time_s) | self.tag

    def alarm_label(self) -> str:
        """The black-box file's label of this loop's alarm."""
        return f"{self.name}-{self.ticker.fault}" if self.tag else self.ticker.fault

    def dm_frames(self, tick: Tick, bus_time_s: float, row: np.ndarray) -> list[can.Message]:
        """This row's DM1/DM2 frames of the loop (none with J1939 off)."""
        if self.diag is None:
            return []
        named = finding(tick.check, tick.sensor)
        return self.diag.tick(
            tick.t_s, bus_time_s, tick.state, self.ticker.fault, row, named, tick.episode_open
        )
