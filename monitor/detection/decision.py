"""The per-sample decision, one path for the live ticker and the offline detector.

Given a sample's J, its residual and what the gating found, one ``Decider.decide`` steps the
alarm machine (``monitor.detection.alarm``) and says whether the monitor's status (alarm
state and gating status) changed, i.e. whether the sample makes an event.  ``event_record``
is the one event-log line both write (``monitor detect --events`` and the daemon's log share
its schema, docs/reference/events.md).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any, NamedTuple

import numpy as np

from monitor.detection.alarm import AlarmConfig, AlarmMachine, Isolator, State
from monitor.detection.gating import status_keys
from monitor.detection.opstate import OpState
from monitor.detection.plausibility import STALE
from monitor.model.machinecard import COMMISSION


class Status(NamedTuple):
    """What an event reports besides J: alarm state and the gating's findings."""

    state: State
    op_state: int  # OpState
    oor: int  # index of the operating signal beyond the trained range, -1: none
    check: int  # plausibility finding (monitor.detection.plausibility), 0: none
    sensor: int  # the sensor it names, -1: none


#: The status of a quiet sample: normal operation, nothing found, no alarm.
QUIET = Status(State.NORMAL, int(OpState.NORMAL), -1, 0, -1)


class Decision(NamedTuple):
    state: State
    changed: bool  # the status differs from the previous sample's (True on the first)
    state_changed: bool  # the alarm state itself changed
    raised: bool = False  # a new alarm episode starts here (black box, DM1 occurrence)
    episode_open: bool = False  # an alarm episode is open (in fault, or in a short gap)
    withheld: bool = False  # an alarm episode would start here, but alarms are withheld


class Decider:
    """One alarm machine and the last status; ``decide`` once per sample, in time order.

    The episode rule lives here, in the one path both detectors take: a fault opens an alarm
    episode; an inactive or sensor-fault gap of at most ``alarm.episode_gap_samples`` (60 s)
    inside it does not end it (the fault comes back with the same isolation, no new black
    box, no new DM1 occurrence); only the clear rule or a longer gap does.  One fault, one
    episode, live and offline alike.

    ``withhold`` (a reason, ``monitor.model.machinecard.reference_reason``): the model is
    another machine's, so its hydraulic alarms are withheld: the alarm machine runs as
    usual, but a fault is reported as normal (no MON_Alarm fault, no DM1, no black box) and
    ``Decision.withheld`` marks where it would have raised an episode.  Sensor faults, which
    do not rest on the model, stay.
    """

    def __init__(
        self,
        alarm: AlarmConfig,
        eps0: float,
        isolator: Isolator | None = None,
        window_n: int = 0,
        withhold: str | None = None,
    ) -> None:
        self.machine = AlarmMachine(alarm, eps0, isolator, window_n)
        self.status: Status | None = None  # of the last sample decided
        self.withhold = withhold

    @property
    def state(self) -> State:
        """The state reported (a withheld fault is reported as normal)."""
        state = self.machine.state
        return State.NORMAL if self.withhold is not None and state is State.FAULT else state

    @property
    def fault(self) -> str:
        return self.machine.fault

    def decide(
        self,
        j: float,
        inputs_ok: bool,
        engine_rpm: float,
        e: np.ndarray | None,
        regime: int,
        op_state: int,
        oor: int = -1,
        check: int = 0,
        sensor: int = -1,
        named: str = "",
    ) -> Decision:
        """Step the alarm machine on one sample: ``inputs_ok`` every model signal present,
        ``check`` the plausibility finding (a finding is a sensor fault), ``op_state`` the
        operating state (warm-up counts as not operating, like the engine off).  A ``STALE``
        finding (EngineSpeed silent, the pump working) counts the engine as running.  The
        engine runs or stops as ``op_state`` reports, which waits for more than one frame of
        evidence (``monitor.detection.evidence``), not as one EngineSpeed reading says.
        ``named``: the fault the statistic setting ``j`` names ("": the isolator's)."""
        sensor_ok = inputs_ok and check == 0
        on = check == STALE or op_state != OpState.ENGINE_OFF
        state = self.machine.step(
            j,
            sensor_ok,
            engine_rpm if on else math.nan,
            e,
            regime,
            op_state != OpState.WARM_UP,
            on,
            named,
        )
        m = self.machine
        raised, episode_open, withheld = m.raised, m.episode_open, False
        if self.withhold is not None:
            withheld, raised, episode_open = raised, False, False
            state = State.NORMAL if state is State.FAULT else state
        status = Status(state, int(op_state), int(oor), int(check), int(sensor))
        prev = self.status
        self.status = status
        changed = prev is None or state is not prev.state
        return Decision(state, status != prev, changed, raised, episode_open, withheld)

    def quiet(self) -> bool:
        """The last sample was quiet: a run of quiet samples may go to ``skip_quiet`` (not
        while a withheld fault holds the alarm machine)."""
        return self.status == QUIET and self.machine.state is State.NORMAL

    def skip_quiet(self, e: np.ndarray, regimes: np.ndarray) -> None:
        """``decide`` over a run of quiet samples (J finite and <= eps0, status ``QUIET``)
        at once; the status stays ``QUIET``."""
        self.machine.skip_quiet(e, regimes)


def wall_time(t_s: float, start_time_s: float | None) -> str | None:
    """The wall clock of ``t_s`` s from the first sample (None without a start time)."""
    if start_time_s is None:
        return None
    return dt.datetime.fromtimestamp(start_time_s + t_s, tz=dt.timezone.utc).isoformat()


def withheld_record(
    t_s: float, level: float, reason: str, start_time_s: float | None
) -> dict[str, Any]:
    """The event line of an alarm withheld (``kind: "withheld"``): ``t`` s from the first
    sample, ``time`` the wall clock (null without a start time), the ``level`` that would
    have raised it (1 = alarm) and the ``reason``."""
    return {
        "kind": "withheld",
        "t": round(float(t_s), 6),
        "time": wall_time(t_s, start_time_s),
        "level": float(level),
        "reason": f"{reason}; {COMMISSION}",
    }


def event_record(
    t_s: float,
    state: State,
    j: float,
    eps0: float,
    fault: str,
    start_time_s: float | None,
    op_state: int = int(OpState.NORMAL),
    out_of_range: str | None = None,
    check: int = 0,
    sensor: int = -1,
    stale_signal: str | None = None,
) -> dict[str, Any]:
    """The JSON-lines event of a state change: ``t`` s from the first sample, ``time`` the
    wall clock (null without a start time), ``state``, ``J`` (null while the window warms up
    or pauses), ``threshold``, ``fault`` (only in fault) and the gating's keys.  A sensor
    fault from missing data names its signal: ``sensor`` it, ``sensor_check`` ``stale``."""
    return {
        "t": round(float(t_s), 6),
        "time": wall_time(t_s, start_time_s),
        "state": state.label,
        "J": float(j) if math.isfinite(j) else None,
        "threshold": float(eps0),
        "fault": fault if state is State.FAULT else None,
        **status_keys(int(op_state), out_of_range, int(check), int(sensor)),
    } | (
        {"sensor": stale_signal, "sensor_check": "stale"}
        if state is State.SENSOR_FAULT and check == 0 and stale_signal
        else {}
    )
