"""When the monitor says what over J1939: DM1 on change and every second, DM2 on request.

One ``tick`` per 100 Hz row, after the alarm state machine, on the sample clock (like
MON_Alarm, so a log replayed at any speed gives the same frames).  The active DTCs follow the
alarm state: in ``fault`` one DTC for the isolated fault, in ``sensor_fault`` one per model
signal that is stale (missing) in the row (and EngineSpeed when the gating names it silent
while the pump works, FMI ``sensor_fmi`` as for any stale signal), kept through the recovery
debounce; none otherwise.  Isolation refines its answer while an alarm lasts and may fall back
to ``unknown`` for a moment: the DTC keeps the last fault it named, so a display sees one
trouble code per alarm, not a flicker.  A DTC counts one occurrence per episode (a stretch with
any DTC active) in which it becomes active, since the start, at most 126; one that goes
inactive joins the previously active DTCs that DM2 reports.

J1939-73: DM1 goes out when the set of active DTCs changes and every second while one is
active; with none, once on the change and, with ``repeat_when_clear``, every second in the
no-DTC form.  A request (PGN 59904) for DM2 or DM1 is answered with it.  One message at a
time: a BAM's data packets go out ``bam_gap_s`` apart before the next message starts.  A
rate cap (``monitor.live.ratecap``) keeps the J1939 frames within ``max_frames_per_s`` in any
second of the sample clock: a message starts only when all its frames fit, each counted when
it goes out; a DM1 it holds back goes out once it allows.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import can
import numpy as np

from monitor.codec.j1939.dtc import OC_MAX, PGN_DM1, PGN_DM2, Dtc, Lamp, dm_payload, lamp_bytes
from monitor.codec.j1939.transport import REQUEST_FILTER, pgn_frames, requested_pgn
from monitor.config.settings import J1939Config
from monitor.detection.alarm import State
from monitor.live.ratecap import RateCap
from monitor.sampling.sampler import ROW_COLUMNS

DM1_PERIOD_S = 1.0  # J1939-73
_EPS = 1e-6  # sample times are sums of 10 ms steps

Key = tuple[int, int]  # (SPN, FMI)


class TroubleCodes:
    """Which DTCs a tick makes active (with their lamps): the isolated fault's in ``fault``,
    the stale or implausible signals' in ``sensor_fault``, none otherwise.

    ``signals``: the model's signals, whose staleness makes a sensor fault (every signal
    name has an SPN: the config merges its map into the defaults)."""

    def __init__(
        self, cfg: J1939Config, signals: tuple[str, ...], columns: tuple[str, ...]
    ) -> None:
        self.cfg = cfg
        self._signals = signals
        self._idx = np.array([1 + columns.index(s) for s in signals], dtype=np.int64)
        self._fault_lamp = Lamp.parse(cfg.fault_lamp, "j1939.fault_lamp")
        self._sensor_lamp = Lamp.parse(cfg.sensor_lamp, "j1939.sensor_lamp")
        self._sensor: dict[Key, Lamp] = {}  # DTCs of the current sensor fault
        self._named: str | None = None  # the last fault isolation named in this alarm
        self._named_episode: str | None = None  # the same, kept through a gap in the episode

    def keys(
        self,
        state: State,
        fault: str,
        row: np.ndarray,
        finding: tuple[str | None, str | None],
        episode_open: bool,
    ) -> dict[Key, Lamp]:
        """The active DTCs of a tick.  While an alarm episode is open (``episode_open``) its
        fault DTC stays active through a short inactive or sensor-fault gap."""
        keys = self._keys(state, fault, row, finding)
        if episode_open and state is not State.FAULT and self._named_episode is not None:
            name = self._named_episode
            keys = keys | {(self.cfg.fault_spn[name], self.cfg.fault_fmi[name]): self._fault_lamp}
        self._named_episode = (
            (self._named or "unknown")
            if state is State.FAULT
            else (self._named_episode if episode_open else None)
        )
        return keys

    def _keys(
        self, state: State, fault: str, row: np.ndarray, finding: tuple[str | None, str | None]
    ) -> dict[Key, Lamp]:
        cfg = self.cfg
        if state is State.FAULT:
            if fault != "unknown" and fault in cfg.fault_spn:
                self._named = fault
            name = self._named or "unknown"
            return {(cfg.fault_spn[name], cfg.fault_fmi[name]): self._fault_lamp}
        self._named = None
        if state is not State.SENSOR_FAULT:
            self._sensor = {}
            return {}
        # The DTCs of this sensor fault: one per stale signal (FMI ``sensor_fmi``), or the
        # signal a plausibility check named (FMI per check); kept through the recovery
        # debounce, when the row is whole again and the finding gone.
        # A silent EngineSpeed (check ``stale``) is named even when the model does not use it.
        stale = np.isnan(row[self._idx])
        signal, check = finding
        if stale.any() or check == "stale":
            names = {s for s, bad in zip(self._signals, stale, strict=True) if bad}
            names |= {signal} if check == "stale" and signal is not None else set()
            self._sensor = {(cfg.sensor_spn[n], cfg.sensor_fmi): self._sensor_lamp for n in names}
        elif signal is not None and check is not None:
            self._sensor = {(cfg.sensor_spn[signal], cfg.check_fmi[check]): self._sensor_lamp}
        return self._sensor or {(cfg.sensor_spn["unknown"], cfg.sensor_fmi): self._sensor_lamp}


class DtcTable:
    """The DTCs active now, previously active (DM2), and how often each became active: one
    occurrence per episode (a stretch with any DTC active), at most 126."""

    def __init__(self) -> None:
        self.active: dict[Key, Lamp] = {}
        self.occurrences: dict[Key, int] = {}
        self.previous: set[Key] = set()  # previously active, not active now (DM2)
        self._counted: set[Key] = set()  # DTCs counted in this episode

    def update(self, keys: dict[Key, Lamp]) -> None:
        for k in keys.keys() - self.active.keys() - self._counted:
            self.occurrences[k] = min(self.occurrences.get(k, 0) + 1, OC_MAX)
        self._counted = (self._counted | keys.keys()) if keys else set()
        self.previous |= self.active.keys() - keys.keys()
        self.previous -= keys.keys()
        self.active = keys

    def _dtcs(self, keys: set[Key] | dict[Key, Lamp]) -> list[Dtc]:
        return [Dtc(spn, fmi, self.occurrences[(spn, fmi)]) for spn, fmi in sorted(keys)]

    def payload(self, pgn: int) -> bytes:
        """The DM1 (active) or DM2 (previously active) payload; lamps as they are now."""
        lamps = lamp_bytes(frozenset(self.active.values()))
        return dm_payload(lamps, self._dtcs(self.active if pgn == PGN_DM1 else self.previous))


class Diagnostics:
    """Builds the DM1/DM2 frames of one monitor (source address ``cfg.source_address``):
    the trouble codes of each tick (``TroubleCodes``) kept in a ``DtcTable``, sent as J1939-73
    says, one message at a time within the rate cap."""

    def __init__(
        self, cfg: J1939Config, signals: tuple[str, ...], columns: tuple[str, ...] = ROW_COLUMNS
    ) -> None:
        self.cfg = cfg
        self.codes = TroubleCodes(cfg, signals, columns)
        self.dtcs = DtcTable()
        self._started = False
        self._want: set[int] = set()  # PGNs to send as soon as possible
        self._held = False
        self._queue: deque[can.Message] = deque()
        self._next_t = 0.0
        self._last_dm1_t = -float("inf")
        self.cap = RateCap(cfg.max_frames_per_s)
        self.sent = {PGN_DM1: 0, PGN_DM2: 0}
        self.frames = 0
        self.held_back = 0  # messages the rate cap delayed
        self.requests = 0

    @property
    def active(self) -> dict[Key, Lamp]:
        return self.dtcs.active

    @property
    def previous(self) -> set[Key]:
        """Previously active DTCs, not active now (DM2)."""
        return self.dtcs.previous

    # -- inputs ---------------------------------------------------------------------------

    def request(self, msg: can.Message) -> bool:
        """Take a request frame; True when it asked for DM1 or DM2 of ours."""
        pgn = requested_pgn(msg, self.cfg.source_address)
        if pgn not in (PGN_DM1, PGN_DM2):
            return False
        self.requests += 1
        self._want.add(pgn)
        return True

    @staticmethod
    def rx_filters() -> list[dict[str, Any]]:
        return [dict(REQUEST_FILTER)]

    # -- the tick ---------------------------------------------------------------------------

    def tick(
        self,
        t_s: float,
        bus_time_s: float,
        state: State,
        fault: str,
        row: np.ndarray,
        finding: tuple[str | None, str | None] = (None, None),
        episode_open: bool = False,
    ) -> list[can.Message]:
        """Frames to send at sample time ``t_s`` (stamped ``bus_time_s``); ``finding`` is the
        plausibility check's (signal, check name) behind a sensor fault, if any.  While an
        alarm episode is open (``episode_open``) its fault DTC stays active through a short
        inactive or sensor-fault gap: one episode, one occurrence."""
        keys = self.codes.keys(state, fault, row, finding, episode_open)
        if not self._started or keys.keys() != self.dtcs.active.keys():
            self.dtcs.update(keys)
            self._want.add(PGN_DM1)
            self._started = True
        out: list[can.Message] = []
        if self._queue:
            if t_s + _EPS >= self._next_t:
                out.append(self._queue.popleft())
                self.cap.record(t_s)
                self._next_t = t_s + self.cfg.bam_gap_s
        else:
            periodic = (self.dtcs.active or self.cfg.repeat_when_clear) and (
                t_s - self._last_dm1_t + _EPS >= DM1_PERIOD_S
            )
            if periodic:
                self._want.add(PGN_DM1)
            if self._want:
                out = self._start(min(self._want), t_s)  # DM1 (65226) before DM2
        for m in out:
            m.timestamp = bus_time_s
        self.frames += len(out)
        return out

    def _start(self, pgn: int, t_s: float) -> list[can.Message]:
        payload = self.dtcs.payload(pgn)
        frames = pgn_frames(pgn, payload, self.cfg.source_address, self.cfg.priority)
        if not self.cap.allows(t_s, len(frames)):
            if not self._held:
                self.held_back += 1
            self._held = True
            return []
        self._held = False
        self.cap.record(t_s)  # the first frame; the others as they go out
        self._want.discard(pgn)
        self.sent[pgn] += 1
        if pgn == PGN_DM1:
            self._last_dm1_t = t_s
        self._queue.extend(frames[1:])
        self._next_t = t_s + self.cfg.bam_gap_s
        return frames[:1]

    def counts(self) -> dict[str, int]:
        return {
            "dm1_messages": self.sent[PGN_DM1],
            "dm2_messages": self.sent[PGN_DM2],
            "j1939_frames": self.frames,
            "j1939_held_back": self.held_back,
            "j1939_requests": self.requests,
        }
