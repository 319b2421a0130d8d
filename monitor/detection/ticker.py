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
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.detection.alarm import AlarmConfig, State, regime_of
from monitor.detection.decision import Decider, event_record
from monitor.detection.gating import Gate, GatingConfig
from monitor.detection.offline import make_isolator
from monitor.detection.opstate import OpState
from monitor.errors import ModelFileError
from monitor.model.dgrnn import TickPredictor
from monitor.model.modelfile import MonitorModel
from monitor.model.statistic import active, raise_level
from monitor.sampling.ring import RowRing
from monitor.sampling.sampler import ROW_COLUMNS


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


class Ticker:
    def __init__(
        self,
        model: MonitorModel,
        alarm: AlarmConfig | None = None,
        horizon: int | None = None,
        columns: tuple[str, ...] = ROW_COLUMNS,
        gating: GatingConfig | None = None,
    ) -> None:
        self.model = model
        self.alarm = alarm or AlarmConfig()
        spec = model.spec
        missing = [n for n in (*spec.variables, "EngineSpeed") if n not in columns]
        if missing:
            raise ModelFileError(f"the model needs signal(s) the rows lack: {missing}")
        self.predictor = TickPredictor(model.dgrnn, horizon)
        self.rows_needed = self.predictor.rows_needed
        # Row layout is [t, *columns]: +1 skips t.
        self._var_idx = np.array([1 + columns.index(v) for v in spec.variables], dtype=np.int64)
        self._names = tuple(spec.variables)
        self._engine_col = 1 + columns.index("EngineSpeed")
        self._spool_col = 1 + columns.index("SpoolCmd") if "SpoolCmd" in columns else -1
        norm_cols = [model.normalizer.names_.index(v) for v in spec.variables]
        self._mean = np.ascontiguousarray(model.normalizer.mean_[norm_cols])
        self._std = np.ascontiguousarray(model.normalizer.std_[norm_cols])
        nvar, nout = len(spec.variables), len(spec.outputs)
        self._raw = np.empty(nvar)
        self._z = np.empty(nvar)
        self._z_out = self._z[:nout]  # a view made once, not per tick
        self._yz = np.empty(nout)
        self._e = np.empty(nout)
        clip = model.residual_clip
        self._clip = None if clip is None else np.asarray(clip, dtype=np.float64)
        self.ring = RowRing(self.rows_needed, nvar)
        # Compile (or load from numba's cache) the kernel now, not on the first live frame:
        # a first-call compile of seconds would back the bus queue up.
        self.predictor.predict(self.ring.last(self.rows_needed), out=self._yz)
        # The statistics of the family (J first: the level rests on it), each with its window
        # over these rows; the alarm machine compares the level, their largest ratio
        # value / threshold, with 1.
        self.stats = active(model)
        self._steps = tuple(s.window(columns, nout).step for s in self.stats)
        self._thresholds = tuple(s.threshold_ for s in self.stats)
        self._index = {s.name: k for k, s in enumerate(self.stats)}
        self._values = [math.nan] * len(self.stats)  # each statistic at the last tick
        self.decider = Decider(self.alarm, 1.0, make_isolator(model), model.window_n)
        self.machine = self.decider.machine
        self.eps0 = float(model.eps0)
        self.gate = Gate(model, self.alarm.min_engine_rpm, gating, columns)
        self.ticks = 0

    @property
    def state(self) -> State:
        return self.machine.state

    @property
    def fault(self) -> str:
        return self.machine.fault

    @property
    def residual(self) -> np.ndarray:
        return self._e

    def value(self, name: str) -> float:
        """Statistic ``name`` (``J``, ``B``, ...) at the last tick (NaN: not judged, not yet,
        or the model has none)."""
        k = self._index.get(name)
        return math.nan if k is None else float(self._values[k])

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
        raw, z, e = self._raw, self._z, self._e
        np.take(row, self._var_idx, out=raw)
        engine = float(row[self._engine_col])
        gate = self.gate
        gate.step(row)
        # A sum is finite exactly when every term is (values are far from overflow).
        inputs_ok = math.isfinite(float(np.add.reduce(raw)))
        np.subtract(raw, self._mean, out=z)
        np.divide(z, self._std, out=z)
        gated = gate.gated_now(inputs_ok)
        if gated:
            z[:] = np.nan  # a gated row (engine off, sensor fault...) must not seed a prediction
        self.ring.push(z)
        self.predictor.predict(self.ring.last(self.rows_needed), out=self._yz)
        np.subtract(self._yz, self._z_out, out=e)
        if self._clip is not None:
            np.clip(e, -self._clip, self._clip, out=e)
        if gated:
            e[:] = np.nan
        values, steps, thresholds = self._values, self._steps, self._thresholds
        j = steps[0](e, row)
        values[0] = j
        level = j / thresholds[0]
        for k in range(1, len(steps)):
            v = steps[k](e, row)
            values[k] = v
            level = raise_level(level, v, thresholds[k])
        spool = float(row[self._spool_col]) if self._spool_col >= 0 else 0.0
        stale = -1 if inputs_ok else int(np.argmax(np.isnan(raw)))
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
            self._names[stale] if stale >= 0 else None,
            d.episode_open,
            level,
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
