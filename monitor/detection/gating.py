"""Which samples the detector may judge: operating state, sensor plausibility, model validity.

One ``Gate`` per detector run holds the three parts (``monitor.detection.opstate``,
``detection.plausibility``, ``model.envelope``) and gives, per sample, the operating state,
the active sensor finding and the out-of-range signal, either for a whole recording
(``series``, ``monitor detect``) or one row at a time (``step``, the daemon's ticker) with
the same numbers.  The operating state is computed from the believed OilTemp and reported
once confirmed (``detection.evidence``): a forged frame changes neither.  EngineSpeed
missing while the pump shows a working machine (``opstate.silent_source``) is a finding of
its own, ``stale`` on EngineSpeed, named before any plausibility finding; the engine then
counts as running.  A sample is *gated* (no prediction is seeded from it and its residual
does not feed J) when the machine is not in normal operation (reported, or computed and not
yet confirmed), a model input is missing, a sensor finding is active, or (with
``validity.gate``) an operating signal is out of range.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.detection.evidence import (
    OilBelief,
    StateConfirmer,
    believed_oil,
    confirmed_states,
)
from monitor.detection.opstate import (
    OperatingConfig,
    OpState,
    OpStateTracker,
    SilenceTracker,
    op_states,
    silent_source,
)
from monitor.detection.plausibility import (
    COLUMNS,
    STALE,
    Plausibility,
    PlausibilityConfig,
    finding,
)
from monitor.io.recording import Recording
from monitor.model.envelope import Validity, ValidityConfig, model_envelope
from monitor.model.modelfile import MonitorModel
from monitor.signals import SAMPLE_PERIOD_S


@dataclass(frozen=True)
class GatingConfig:
    """The ``operating``, ``plausibility`` and ``validity`` sections together."""

    operating: OperatingConfig = field(default_factory=OperatingConfig)
    plausibility: PlausibilityConfig = field(default_factory=PlausibilityConfig)
    validity: ValidityConfig = field(default_factory=ValidityConfig)


@dataclass
class GateSeries:
    """Per sample: ``op_state`` (OpState), ``check``/``sensor`` (plausibility finding code
    and column, 0/-1 for none; ``STALE`` on EngineSpeed for a silent source), ``oor``
    (index into ``Validity.signals`` of the signal out of the trained range in normal
    operation, -1 for none); ``computed`` the operating state the readings show before its
    confirmation (None: the same as ``op_state``)."""

    op_state: np.ndarray
    check: np.ndarray
    sensor: np.ndarray
    oor: np.ndarray
    computed: np.ndarray | None = None


def status_keys(op_state: int, oor_signal: str | None, check: int, sensor: int) -> dict[str, Any]:
    """The event-log keys this module adds (shared by ``monitor detect`` and the daemon)."""
    name, check_name = finding(check, sensor)
    return {
        "op_state": OpState(op_state).label,
        "out_of_range": oor_signal is not None,
        "out_of_range_signal": oor_signal,
        "sensor": name,
        "sensor_check": check_name,
    }


class Gate:
    def __init__(
        self,
        model: MonitorModel,
        min_engine_rpm: float,
        cfg: GatingConfig | None = None,
        columns: tuple[str, ...] | None = None,
    ) -> None:
        cfg = cfg or GatingConfig()
        self.cfg = cfg
        self.min_engine_rpm = float(min_engine_rpm)
        self.tracker = OpStateTracker(min_engine_rpm, cfg.operating)
        self.plausibility = Plausibility(cfg.plausibility, min_engine_rpm)
        plaus = cfg.plausibility
        self._settle_n = round(cfg.operating.silent_settle_s / SAMPLE_PERIOD_S)
        self.silence = SilenceTracker(plaus.rest_max_bar, plaus.move_flow_lpm, self._settle_n)
        op = cfg.operating
        samples = lambda s: round(s / SAMPLE_PERIOD_S)  # noqa: E731
        self._oil_args = (op.oil_rate_max_c_per_s, samples(op.oil_confirm_s))
        self._confirm_args = (samples(op.engine_confirm_s), samples(op.oil_confirm_s))
        self.oil_belief = OilBelief(*self._oil_args)
        self.confirmer = StateConfirmer(*self._confirm_args)
        self._engine_col = COLUMNS.index("EngineSpeed")
        self.validity = Validity(model_envelope(model), cfg.validity)
        self.gate_oor = cfg.validity.gate
        # Live rows: [t, *columns] copied into a (1, width + 1) buffer whose last entry is
        # NaN, so a signal the rows lack reads as missing without a branch per tick.
        if columns is not None:
            width = 1 + len(columns)
            pos = {name: 1 + k for k, name in enumerate(columns)}
            self._ext = np.full((1, width + 1), np.nan)
            self._ext_row = self._ext[0]
            self._ext_head = self._ext[0, :width]
            self._plaus_idx = np.array([pos.get(n, width) for n in COLUMNS], dtype=np.int64)
            self._val_idx = tuple(pos.get(n, width) for n in self.validity.signals)
            self._engine = pos.get("EngineSpeed", width)
            self._oil = pos.get("OilTemp", width)
            self._has_oil = "OilTemp" in pos
            self._pp = pos.get("PP", width)
            self._qp = pos.get("QP", width)
        self.op_state = OpState.NORMAL
        self.computed = OpState.NORMAL
        self.check = 0
        self.sensor = -1
        self.oor = -1

    def carry_over(self, old: Gate) -> None:
        """A reload: keep what the rows so far have built up (operating state, plausibility
        history) when its settings are unchanged; those do not depend on the model."""
        if old.cfg == self.cfg and old.min_engine_rpm == self.min_engine_rpm:
            self.tracker, self.plausibility = old.tracker, old.plausibility
            self.silence = old.silence
            self.oil_belief, self.confirmer = old.oil_belief, old.confirmer
            self.op_state, self.check, self.sensor = old.op_state, old.check, old.sensor
            self.computed = old.computed

    # -- offline --------------------------------------------------------------------------

    def series(self, rec: Recording) -> GateSeries:
        n = len(rec)

        def col(name: str) -> np.ndarray:
            return rec[name] if rec.has(name) else np.full(n, np.nan)

        plaus = self.cfg.plausibility
        engine = col("EngineSpeed")
        silent = silent_source(
            engine, col("PP"), col("QP"), plaus.rest_max_bar, plaus.move_flow_lpm, self._settle_n
        )
        # A silent source is not an engine off: the pump shows the engine running.
        running = np.where(silent, self.min_engine_rpm, engine)
        oil = believed_oil(col("OilTemp"), *self._oil_args)
        computed = op_states(running, oil, self.min_engine_rpm, self.cfg.operating)
        ops = confirmed_states(computed, np.isnan(engine), *self._confirm_args)
        # Downstream of the gate's own readings the believed OilTemp stands in for the raw.
        x = np.column_stack([oil if c == "OilTemp" else col(c) for c in COLUMNS])
        check, sensor = self.plausibility.series(x)
        check[silent] = STALE
        sensor[silent] = self._engine_col
        oor = self.validity.series(self.validity_values(rec, oil))
        oor[(ops != OpState.NORMAL) | (computed != OpState.NORMAL)] = -1
        return GateSeries(ops, check, sensor, oor, computed)

    def validity_values(self, rec: Recording, oil_c: np.ndarray | None = None) -> np.ndarray:
        """The validity signals' values per sample (``oil_c``: OilTemp to use instead)."""
        n = len(rec)
        cols = [
            oil_c
            if s == "OilTemp" and oil_c is not None
            else rec[s]
            if rec.has(s)
            else np.full(n, np.nan)
            for s in self.validity.signals
        ]
        return np.column_stack(cols) if cols else np.empty((n, 0))

    def gated(self, g: GateSeries, inputs_ok: np.ndarray) -> np.ndarray:
        """Samples that neither seed a prediction nor feed J."""
        mask = (g.op_state != OpState.NORMAL) | ~inputs_ok | (g.check != 0)
        if g.computed is not None:
            mask |= g.computed != OpState.NORMAL
        if self.gate_oor:
            mask |= g.oor >= 0
        return mask

    # -- live -----------------------------------------------------------------------------

    def step(self, row: np.ndarray) -> None:
        """One row ``[t, *columns]``: sets ``op_state``, ``check``/``sensor`` and ``oor``."""
        ext = self._ext_row
        np.copyto(self._ext_head, row)
        engine = float(ext[self._engine])
        silent = self.silence.step(engine, float(ext[self._pp]), float(ext[self._qp]))
        oil = self.oil_belief.step(float(ext[self._oil]))
        if self._has_oil:
            ext[self._oil] = oil  # the believed OilTemp for every check below
        self.computed = self.tracker.step(self.min_engine_rpm if silent else engine, oil)
        op = OpState(self.confirmer.step(self.computed, engine != engine))
        self.check = self.plausibility.step(self._ext, self._plaus_idx)
        self.sensor = self.plausibility.signal
        if silent:
            self.check, self.sensor = STALE, self._engine_col
        normal = op is OpState.NORMAL and self.computed is OpState.NORMAL
        self.oor = self.validity.check(ext, self._val_idx) if normal else -1
        self.op_state = op

    def gated_now(self, inputs_ok: bool) -> bool:
        return (
            self.op_state is not OpState.NORMAL
            or self.computed is not OpState.NORMAL
            or not inputs_ok
            or self.check != 0
            or (self.gate_oor and self.oor >= 0)
        )

    def oor_name(self, oor: int) -> str | None:
        return self.validity.signals[oor] if oor >= 0 else None
