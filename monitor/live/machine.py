"""The daemon's machine-level parts, beside its loops: the pump rule on the shared row
(``monitor.detection.pump``, the config's ``pump:``) with its alarm frame (MON_Alarm_Pump)
and, with J1939 on, its DM1 at ``pump.source_address`` (``pump_wear``'s DTC in fault, as a
loop's alarm raises its fault's), and the machine's finding over every loop's and the pump's alarms
(``monitor.detection.machine``), said as an event line when it changes.

Per row the pump rule costs a few float operations per section on the row as a list; the
finding is fed only when an alarm is raised or cleared.  A reload (SIGHUP) keeps both: the
pump model is read at start.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import can
import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.config.pump import PUMP_ALARM_SIGNALS, load_pump, pump_columns
from monitor.config.settings import MonitorConfig
from monitor.detection.alarm import State
from monitor.detection.decision import wall_time
from monitor.detection.machine import Alarm, MachineFinding
from monitor.detection.pump import PUMP, PUMP_FAULT, PumpRule
from monitor.errors import ConfigError
from monitor.live.dm1 import Diagnostics
from monitor.live.outputs import AlarmFrames

Say = Callable[[dict[str, Any]], None]
Send = Callable[[can.Message], None]


class PumpFrames(AlarmFrames):
    """MON_Alarm_Pump: MON_Alarm's timing and rate cap, the pump's signals."""

    def pump_alarm(self, rule: PumpRule, bus_time_s: float) -> can.Message:
        fault = rule.state is State.FAULT
        code = self.codes.get(PUMP_FAULT, 15) if fault else 0
        stat, threshold = rule.stat_bar, rule.threshold_bar
        values = {
            "State": int(rule.state),
            "Fault": code,
            "MarginResidual": min(max(stat, -32.0), 32.0) if stat == stat else 0.0,
            "Threshold": min(threshold, 65.0) if threshold == threshold else 0.0,
            "AlarmCount": self.alarm_count % 16,
        }
        return self.codec.encode_message(self.message, values, bus_time_s)


class MachineWatch:
    """The pump rule (None without ``pump:``) and the machine's finding."""

    def __init__(self, cfg: MonitorConfig, codec: FrameCodec, columns: tuple[str, ...]) -> None:
        self.finding = MachineFinding()
        self.rule: PumpRule | None = None
        self.frames: PumpFrames | None = None
        self.diag: Diagnostics | None = None
        model = load_pump(cfg)
        if model is None or cfg.pump is None:
            return
        message = cfg.pump.alarm_message
        info = codec.messages.get(message)
        missing = [s for s in PUMP_ALARM_SIGNALS if info is None or s not in info.signal_names]
        if missing:
            raise ConfigError(
                f"{cfg.source}: pump.alarm_message: {message} in {cfg.dbc} lacks "
                f"{', '.join(missing)}"
            )
        self.rule = PumpRule(model, pump_columns(cfg, columns))
        self.frames = PumpFrames(codec, cfg.outputs, message)
        if cfg.j1939.enabled:
            # The pump's own DM1/DM2, as each loop has: pump_wear's DTC while in fault.
            address = cfg.pump.source_address
            taken = [lc.name for lc in cfg.monitored_loops if lc.source_address == address]
            if taken:
                raise ConfigError(
                    f"{cfg.source}: pump.source_address {address} is loop {taken[0]}'s; "
                    "the pump's DM1 needs an address of its own"
                )
            j1939 = replace(cfg.j1939, source_address=address)
            self.diag = Diagnostics(j1939, (), columns)

    def tick(
        self, row: np.ndarray, bus_time_s: float, start_s: float | None, send: Send, say: Say
    ) -> None:
        """One row: the pump rule, its frame when due, its event and the finding's."""
        rule, frames = self.rule, self.frames
        if rule is None or frames is None:
            return
        changed = rule.tick(row.tolist())
        t_s = float(row[0])
        if frames.due(t_s, rule.state, changed):
            send(frames.pump_alarm(rule, bus_time_s))
        if self.diag is not None:
            for msg in self.diag.tick(t_s, bus_time_s, rule.state, PUMP_FAULT, row):
                send(msg)
        if not changed:
            return
        say(rule.event(t_s, wall_time(t_s, start_s)))
        if rule.state is State.FAULT:
            alarm = Alarm(PUMP, t_s, rule.level, rule.window_start_s)
            self.raised(alarm, start_s, say)
        else:
            self.cleared(PUMP, t_s, start_s, say)

    def raised(self, alarm: Alarm, start_s: float | None, say: Say) -> None:
        if self.finding.raised(alarm):
            say(self._event(alarm.t_s, start_s))

    def cleared(self, source: str, t_s: float, start_s: float | None, say: Say) -> None:
        if self.finding.cleared(source):
            say(self._event(t_s, start_s))

    def _event(self, t_s: float, start_s: float | None) -> dict[str, Any]:
        """``kind: finding``: what the machine's alarms name now (``named`` null: none)."""
        return {
            "kind": "finding",
            **self.finding.finding.as_dict(),
            "t": round(t_s, 6),
            "time": wall_time(t_s, start_s),
        }

    @property
    def counts(self) -> dict[str, int]:
        if self.rule is None or self.frames is None:
            return {}
        out = {"pump_alarms": self.rule.alarms, "pump_alarm_frames": self.frames.sent}
        if self.diag is not None:
            out["pump_dm1_messages"] = self.diag.counts()["dm1_messages"]
        return out

    @property
    def state(self) -> State | None:
        """The pump rule's state (None: no pump rule), for MON_Status."""
        return None if self.rule is None else self.rule.state
