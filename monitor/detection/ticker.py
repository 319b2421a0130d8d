"""The live detector: one ``tick`` per 100 Hz row of the sample clock.

It reproduces ``monitor.detection.offline.detect`` sample by sample, so a log gives the same events
on the bus as at a desk: z-score with the model's F0 statistics; a row outside normal
operation (engine off, warm-up), with a model signal missing, a sensor finding active or an
operating signal out of the trained range is gated (``monitor.detection.gating``: NaN before
prediction, so it never feeds one, and its residual is NaN); e = y_hat - y in z units,
clipped to the model's residual bound; J by the incremental window (eq. 9) and every other
statistic of the family (``monitor.model.statistic``) by its own; one ``AlarmMachine.step``
per row.  Nothing is allocated per tick beyond numpy scalars.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.detection.alarm import AlarmConfig, AlarmMachine, State, regime_of
from monitor.detection.decision import Decider, event_record, withheld_record
from monitor.detection.gating import Gate, GatingConfig
from monitor.detection.offline import make_isolator
from monitor.detection.opstate import OpState
from monitor.errors import ModelFileError
from monitor.model.dgrnn import TickPredictor
from monitor.model.modelfile import MonitorModel
from monitor.model.statistic import active, raise_level
from monitor.sampling.ring import RowRing
from monitor.sampling.sampler import ROW_COLUMNS
from monitor.signals import ROD_SPEED, ROD_SPEED_SPAN, rod_speed_mm_s, source_signal


@dataclass
class Tick:
    """What one row produced (the buffers behind ``e`` are reused by the next tick)."""

    t_s: float  # sample-clock time of the row (s from the first frame)
    state: State
    j: float  # NaN while the window warms up or pauses
    changed: bool  # state or gating status differs from the previous tick's (True on the first)
    op_state: OpState = OpState.NORMAL
    out_of_range: str | None = None  # the operating signal beyond the trained range
    check: int = 0  # plausibility finding (monitor.detection.plausibility), 0: none
    sensor: int = -1
    state_changed: bool = True  # the alarm state itself changed (``changed`` also covers gating)
    raised: bool = False  # a new alarm episode starts at this row
    stale_signal: str | None = None  # the first model signal missing, when inputs are not ok
    episode_open: bool = False  # an alarm episode is open (fault, or a short gap within one)
    level: float = math.nan  # compared with 1: each statistic's value / threshold, the largest
    withheld: bool = False  # a reference model's alarm would have been raised here: withheld


class _Inputs:
    """Reads a row's model signals and z-scores them with the model's F0 statistics, into
    buffers made once."""

    def __init__(self, model: MonitorModel, columns: tuple[str, ...]) -> None:
        spec = model.spec
        # Row layout is [t, *columns]: +1 skips t.  A derived signal (RodSpeed) is read from
        # the column it is computed from (``monitor.signals.DERIVED``).
        sources = tuple(source_signal(v) for v in spec.variables)
        self.var_idx = np.array([1 + columns.index(v) for v in sources], dtype=np.int64)
        self.names = sources  # what goes stale is the measured signal
        speed = ROD_SPEED.name
        self.speed_at = spec.variables.index(speed) if speed in spec.variables else -1
        # RodPos of the last ROD_SPEED_SPAN rows, oldest at ``pos_next`` (empty: no row yet).
        self.pos_ring: list[float] = []
        self.pos_next = 0
        self.engine_col = 1 + columns.index("EngineSpeed")
        self.spool_col = 1 + columns.index("SpoolCmd") if "SpoolCmd" in columns else -1
        norm_cols = [model.normalizer.names_.index(v) for v in spec.variables]
        self.mean = np.ascontiguousarray(model.normalizer.mean_[norm_cols])
        self.std = np.ascontiguousarray(model.normalizer.std_[norm_cols])
        self.raw = np.empty(len(spec.variables))
        self.z = np.empty(len(spec.variables))

    def read(self, row: np.ndarray) -> bool:
        """``raw`` and ``z`` from ``row``; True when every model signal is present."""
        raw, z = self.raw, self.z
        np.take(row, self.var_idx, out=raw)
        if self.speed_at >= 0:
            self._rod_speed(raw)
        np.subtract(raw, self.mean, out=z)
        np.divide(z, self.std, out=z)
        # A sum is finite exactly when every term is (values are far from overflow).
        return math.isfinite(float(np.add.reduce(raw)))

    def _rod_speed(self, raw: np.ndarray) -> None:
        """RodPos (read into ``raw[speed_at]``) becomes the rod speed over the last
        ``ROD_SPEED_SPAN`` rows, as ``Recording`` derives it offline."""
        k = self.speed_at
        pos = float(raw[k])
        if not self.pos_ring:  # the first rows span back to the first row
            self.pos_ring = [pos] * ROD_SPEED_SPAN
        raw[k] = rod_speed_mm_s(pos, self.pos_ring[self.pos_next])
        self.pos_ring[self.pos_next] = pos
        self.pos_next = (self.pos_next + 1) % ROD_SPEED_SPAN

    def stale_signal(self) -> str:
        """The first model signal missing from the last row read (one not finite)."""
        return self.names[int(np.argmax(np.isnan(self.raw)))]


class _Residual:
    """The DGRNN's prediction from the ring of past z-rows and e = y_hat - y (z units),
    clipped to the model's residual bound."""

    def __init__(self, model: MonitorModel, horizon: int | None, z: np.ndarray) -> None:
        nout = len(model.spec.outputs)
        self.predictor = TickPredictor(model.dgrnn, horizon)
        self.rows_needed = self.predictor.rows_needed
        self.ring = RowRing(self.rows_needed, len(model.spec.variables))
        self.z_out = z[:nout]  # a view made once, not per tick
        self.yz = np.empty(nout)
        self.e = np.empty(nout)
        clip = model.residual_clip
        self.clip = None if clip is None else np.asarray(clip, dtype=np.float64)
        # Compile (or load from numba's cache) the kernel now, not on the first live frame:
        # a first-call compile of seconds would back the bus queue up.
        self.predictor.predict(self.ring.last(self.rows_needed), out=self.yz)

    def step(self, z: np.ndarray, gated: bool) -> np.ndarray:
        """Push ``z`` (NaN when gated: it must not seed a prediction) and return e."""
        if gated:
            z[:] = np.nan
        self.ring.push(z)
        self.predictor.predict(self.ring.last(self.rows_needed), out=self.yz)
        e = self.e
        np.subtract(self.yz, self.z_out, out=e)
        if self.clip is not None:
            np.clip(e, -self.clip, self.clip, out=e)
        if gated:
            e[:] = np.nan
        return e


class _Family:
    """The statistics of the family (J first: the level rests on it), each with its window
    over the rows; the level is their largest ratio value / threshold (beyond the envelope's
    oil, where J is not judged, the members judging there set it alone: ``level_series``)."""

    def __init__(self, model: MonitorModel, columns: tuple[str, ...]) -> None:
        nout = len(model.spec.outputs)
        self.stats = active(model)
        windows = [s.window(columns, nout) for s in self.stats]
        self.steps = tuple(w.step for w in windows)
        # Members judging beyond the envelope's oil (``Statistic.beyond_oil``): their step.
        self.beyond: dict[int, Callable[[np.ndarray, np.ndarray, float], float]] = {
            k: w.step_beyond  # type: ignore[attr-defined]
            for k, (s, w) in enumerate(zip(self.stats, windows, strict=True))
            if s.beyond_oil
        }
        self.thresholds = tuple(s.threshold_ for s in self.stats)
        self.index = {s.name: k for k, s in enumerate(self.stats)}
        self.values = [math.nan] * len(self.stats)  # each statistic at the last tick
        self.names = tuple(s.names for s in self.stats)
        self.named = ""  # the fault the statistic setting the level names (naming_series)

    def step(
        self, e: np.ndarray, row: np.ndarray, beyond_c: float = math.nan
    ) -> tuple[float, float]:
        """(J, level) of this row; ``beyond_c``: its OilTemp (degC) where the envelope gated
        it for that alone, NaN elsewhere."""
        values, steps, thresholds = self.values, self.steps, self.thresholds
        j = steps[0](e, row)
        values[0] = j
        level = j / thresholds[0]
        named = self.names[0]
        for k in range(1, len(steps)):
            wide = self.beyond.get(k)
            v = steps[k](e, row) if wide is None else wide(e, row, beyond_c)
            values[k] = v
            thr = thresholds[k]
            if wide and level != level and beyond_c == beyond_c and v == v and thr == thr:
                level = v / thr  # beyond the envelope's oil: this member alone
                named = self.names[k]
                continue
            raised = raise_level(level, v, thr)
            if raised > level:  # False with NaN: as ``naming_series``
                named = self.names[k]
            level = raised
        self.named = named
        return j, level

    def value(self, name: str) -> float:
        k = self.index.get(name)
        return math.nan if k is None else float(self.values[k])


class Ticker:
    def __init__(
        self,
        model: MonitorModel,
        alarm: AlarmConfig | None = None,
        horizon: int | None = None,
        columns: tuple[str, ...] = ROW_COLUMNS,
        gating: GatingConfig | None = None,
        reference: str | None = None,
    ) -> None:
        self.model = model
        #: Why ``model`` is another machine's (``machinecard.reference_reason``): its
        #: hydraulic alarms are withheld (``Decider``); None: this machine's own model.
        self.reference = reference
        self.alarm = alarm or AlarmConfig()
        needed = (*map(source_signal, model.spec.variables), "EngineSpeed")
        missing = [n for n in needed if n not in columns]
        if missing:
            raise ModelFileError(f"the model needs signal(s) the rows lack: {missing}")
        self._inputs = _Inputs(model, columns)
        self._residual = _Residual(model, horizon, self._inputs.z)
        self._family = _Family(model, columns)
        self.decider = Decider(self.alarm, 1.0, make_isolator(model), model.window_n, reference)
        self.eps0 = float(model.eps0)
        self.gate = Gate(model, self.alarm.min_engine_rpm, gating, columns)
        self.ticks = 0

    @property
    def machine(self) -> AlarmMachine:
        return self.decider.machine

    @property
    def state(self) -> State:
        return self.decider.state  # as reported: a withheld fault is normal

    @property
    def fault(self) -> str:
        return self.machine.fault

    @property
    def residual(self) -> np.ndarray:
        return self._residual.e

    def value(self, name: str) -> float:
        """Statistic ``name`` (``J``, ``B``, ...) at the last tick (NaN: not judged, not yet,
        or the model has none)."""
        return self._family.value(name)

    def carry_over(self, old: Ticker) -> None:
        """A reload: this ticker (a new model or new settings) goes on from ``old``'s alarm
        state, status and gating, so a reload never clears an alarm by itself.  Its J window
        starts empty; while it fills J is NaN and the alarm state holds, and only then does
        the new model judge (raise, hold or clear by the usual rules)."""
        self.machine.carry_over(old.machine)
        self.decider.status = old.decider.status
        self.gate.carry_over(old.gate)

    def tick(self, row: np.ndarray) -> Tick:
        """Advance one sample: ``row`` is a sampler row ``[t, *columns]``."""
        inp, gate = self._inputs, self.gate
        inputs_ok = inp.read(row)
        engine = float(row[inp.engine_col])
        gate.step(row)
        e = self._residual.step(inp.z, gate.gated_now(inputs_ok))
        j, level = self._family.step(e, row, gate.beyond_now(inputs_ok))
        spool = float(row[inp.spool_col]) if inp.spool_col >= 0 else 0.0
        d = self.decider.decide(
            level,
            inputs_ok,
            engine,
            e,
            regime_of(spool),
            gate.op_state,
            gate.oor,
            gate.check,
            gate.sensor,
            self._family.named,
        )
        self.ticks += 1
        return Tick(
            float(row[0]),
            d.state,
            j,
            d.changed,
            gate.op_state,
            gate.oor_name(gate.oor),
            gate.check,
            gate.sensor,
            d.state_changed,
            d.raised,
            None if inputs_ok else inp.stale_signal(),
            d.episode_open,
            level,
            d.withheld,
        )


def event(tick: Tick, fault: str, eps0: float, start_time_s: float | None) -> dict[str, Any]:
    """The JSON-lines event of a state change, schema shared with ``monitor detect``."""
    return event_record(
        tick.t_s,
        tick.state,
        tick.j,
        eps0,
        fault,
        start_time_s,
        tick.op_state,
        tick.out_of_range,
        tick.check,
        tick.sensor,
        tick.stale_signal,
    )


def withheld_event(tick: Tick, reason: str, start_time_s: float | None) -> dict[str, Any]:
    """The JSON-lines event of an alarm withheld at ``tick`` (``Tick.withheld``), as
    ``monitor detect``'s summary ``withheld`` tells it."""
    return withheld_record(tick.t_s, tick.level, reason, start_time_s)
