"""What the monitor puts out: MON_Alarm and MON_Status frames, and the event log.

MON_Alarm goes out on every state change and is repeated every ``alarm_repeat_s`` while in
fault, both timed on the sample clock so a replayed log gives the same frames at any speed.
A rate cap (``monitor.live.ratecap``, at most ``alarm_max_per_s`` in any second of the sample
clock) holds whatever the state does (a flapping sensor must not flood the bus); a state
change held back by the cap is sent as soon as it allows, with the state current at that
moment.
"""

from __future__ import annotations

import can

from monitor.codec.frames import FrameCodec
from monitor.config.settings import OutputConfig
from monitor.detection.alarm import State
from monitor.live.eventlog import EventLog  # noqa: F401  (the event log lives there now)
from monitor.live.ratecap import RateCap

ALARM = "MON_Alarm"
STATUS = "MON_Status"


def fault_codes(codec: FrameCodec, message: str = ALARM) -> dict[str, int]:
    """Fault name -> MON_Alarm.Fault code, from the DBC's value table."""
    sig = codec.message(message).dbc_message.get_signal_by_name("Fault")
    return {str(name): int(code) for code, name in (sig.choices or {}).items()}


class AlarmFrames:
    """Builds the monitor's frames and decides when MON_Alarm is due (``message``: the
    alarm message of this loop, MON_Alarm's layout; ``monitor.live.loops``)."""

    def __init__(self, codec: FrameCodec, cfg: OutputConfig, message: str = ALARM) -> None:
        self.codec = codec
        self.cfg = cfg
        self.message = message
        self.codes = fault_codes(codec, message)
        self.alarm_count = 0  # hydraulic alarms raised (wraps at 256 in the frame)
        self.sent = 0
        self.held_back = 0  # state changes delayed by the rate cap
        self._last_sent_t = -float("inf")
        self._cap = RateCap(cfg.alarm_max_per_s)
        self._pending = False

    def due(self, t_s: float, state: State, changed: bool) -> bool:
        """Whether a MON_Alarm should go out at sample time ``t_s``."""
        if changed and state is State.FAULT:
            self.alarm_count += 1
        want = (
            changed
            or self._pending
            or (state is State.FAULT and t_s - self._last_sent_t >= self.cfg.alarm_repeat_s)
        )
        if not want:
            return False
        if not self._cap.take(t_s):
            if changed:
                self.held_back += 1
            self._pending = True
            return False
        self._pending = False
        self._last_sent_t = t_s
        self.sent += 1
        return True

    def alarm(
        self, state: State, j: float, eps0: float, fault: str, bus_time_s: float
    ) -> can.Message:
        code = self.codes.get(fault, self.codes.get("unknown", 15)) if state is State.FAULT else 0
        values = {
            "State": int(state),
            "Fault": code,
            "J": j if j == j else 0.0,  # NaN (warm-up) goes out as 0; the state says why
            "Threshold": eps0,
            "AlarmCount": self.alarm_count % 16,
        }
        return self.codec.encode_message(self.message, values, bus_time_s)

    def status(
        self,
        state: State,
        rx: int,
        rejected: int,
        dropped: int,
        bus_time_s: float,
        op_state: int = 0,
        out_of_range: bool = False,
        sensor_check: bool = False,
        bus_events: int = 0,
        disk_error: bool = False,
        pump_fault: bool = False,
    ) -> can.Message:
        """``op_state`` (monitor.detection.opstate.OpState), ``out_of_range`` (outside the model's
        training envelope) and ``sensor_check`` (a named plausibility finding active, even
        while the state shows inactive) go into MON_Status's OpState, OutOfRange and
        SensorCheck; ``bus_events`` (link down, bus-off, error-passive since the start) into
        the wrapping BusEvents counter; ``disk_error`` (a write of the event log or a black
        box failed since the last MON_Status, or events wait in memory for the disk) into
        DiskError; ``pump_fault`` (the pump rule in fault) into PumpFault where the DBC's
        MON_Status has it (dbc/excavator4.dbc)."""
        # Counters wrap (the DBC says so): a receiver looks at differences.
        values = {
            "State": int(state),
            "RxFrames": rx % 65536,
            "RejectedFrames": rejected % 65536,
            "DroppedFrames": dropped % 256,
            "OpState": int(op_state),
            "OutOfRange": int(bool(out_of_range)),
            "SensorCheck": int(bool(sensor_check)),
            "BusEvents": bus_events % 16,
            "DiskError": int(bool(disk_error)),
        }
        if "PumpFault" in self.codec.messages[STATUS].signal_names:
            values["PumpFault"] = int(bool(pump_fault))
        return self.codec.encode_message(STATUS, values, bus_time_s)
