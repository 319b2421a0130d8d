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

import dataclasses
import math
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
    confirmation (None: the same as ``op_state``); ``oil_c`` the believed OilTemp."""

    op_state: np.ndarray
    check: np.ndarray
    sensor: np.ndarray
    oor: np.ndarray
    computed: np.ndarray | None = None
    oil_c: np.ndarray | None = None  # the believed OilTemp, degC (None: not kept)


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


@dataclass(frozen=True)
class _Samples:
    """The ``operating`` section's times as 100 Hz sample counts, as the trackers take them."""

    settle_n: int  # silent_settle_s
    oil_rate_max_c_per_s: float
    oil_confirm_n: int
    engine_confirm_n: int

    @classmethod
    def of(cls, op: OperatingConfig) -> _Samples:
        n = lambda s: round(s / SAMPLE_PERIOD_S)  # noqa: E731
        return cls(
            n(op.silent_settle_s),
            op.oil_rate_max_c_per_s,
            n(op.oil_confirm_s),
            n(op.engine_confirm_s),
        )

    @property
    def oil_args(self) -> tuple[float, int]:
        return self.oil_rate_max_c_per_s, self.oil_confirm_n

    @property
    def confirm_args(self) -> tuple[int, int]:
        return self.engine_confirm_n, self.oil_confirm_n


class _Trackers:
    """What the rows so far have built up: operating state (computed and confirmed), the
    believed OilTemp, a silent EngineSpeed and the plausibility checks.  None of it depends
    on the model, so a reload with unchanged settings keeps it."""

    def __init__(self, min_engine_rpm: float, cfg: GatingConfig, n: _Samples) -> None:
        plaus = cfg.plausibility
        self.op_state = OpStateTracker(min_engine_rpm, cfg.operating)
        self.plausibility = Plausibility(plaus, min_engine_rpm)
        self.silence = SilenceTracker(
            plaus.rest.rest_max_bar, plaus.motion.move_flow_lpm, n.settle_n
        )
        self.oil_belief = OilBelief(*n.oil_args)
        self.confirmer = StateConfirmer(*n.confirm_args)


class _RowLayout:
    """Where the gate's signals sit in a live row ``[t, *columns]``.  Rows are copied into
    a (1, width + 1) buffer whose last entry is NaN, so a signal the rows lack reads as
    missing without a branch per tick."""

    def __init__(self, columns: tuple[str, ...], validity_signals: tuple[str, ...]) -> None:
        width = 1 + len(columns)
        pos = {name: 1 + k for k, name in enumerate(columns)}
        self.ext = np.full((1, width + 1), np.nan)
        self.row = self.ext[0]
        self.head = self.ext[0, :width]
        self.plaus_idx = np.array([pos.get(n, width) for n in COLUMNS], dtype=np.int64)
        self.val_idx = tuple(pos.get(n, width) for n in validity_signals)
        self.engine = pos.get("EngineSpeed", width)
        self.oil = pos.get("OilTemp", width)
        self.has_oil = "OilTemp" in pos
        self.pp = pos.get("PP", width)
        self.qp = pos.get("QP", width)

    def load(self, row: np.ndarray) -> np.ndarray:
        """``row`` copied into the buffer; returns the buffer's row."""
        np.copyto(self.head, row)
        return self.row


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
        self._n = _Samples.of(cfg.operating)
        self._trackers = _Trackers(self.min_engine_rpm, cfg, self._n)
        self._engine_col = COLUMNS.index("EngineSpeed")
        self.validity = Validity(model_envelope(model), cfg.validity)
        self.gate_oor = cfg.validity.gate
        self._layout = None if columns is None else _RowLayout(columns, self.validity.signals)
        self.op_state = OpState.NORMAL
        self.computed = OpState.NORMAL
        self.check = 0
        self.sensor = -1
        self.oor = -1
        self.oil_c = math.nan  # the believed OilTemp of the last row
        # The envelope's OilTemp among its signals (-1: none); the last of them, so an
        # ``oor`` naming it names nothing else out of range (``Validity.series``: the first).
        names = self.validity.signals
        self._oil_index = names.index("OilTemp") if names and names[-1] == "OilTemp" else -1

    def carry_over(self, old: Gate) -> None:
        """A reload: keep what the rows so far have built up (operating state, plausibility
        history) when its settings are unchanged; those do not depend on the model."""
        if old.cfg == self.cfg and old.min_engine_rpm == self.min_engine_rpm:
            self._trackers = old._trackers
            self.op_state, self.check, self.sensor = old.op_state, old.check, old.sensor
            self.computed = old.computed

    # -- offline --------------------------------------------------------------------------

    def series(self, rec: Recording) -> GateSeries:
        n = len(rec)

        def col(name: str) -> np.ndarray:
            return rec[name] if rec.has(name) else np.full(n, np.nan)

        plaus = self.cfg.plausibility
        engine = col("EngineSpeed")
        rest_max_bar, move_flow_lpm = plaus.rest.rest_max_bar, plaus.motion.move_flow_lpm
        silent = silent_source(
            engine, col("PP"), col("QP"), rest_max_bar, move_flow_lpm, self._n.settle_n
        )
        # A silent source is not an engine off: the pump shows the engine running.
        running = np.where(silent, self.min_engine_rpm, engine)
        oil = believed_oil(col("OilTemp"), *self._n.oil_args)
        computed = op_states(running, oil, self.min_engine_rpm, self.cfg.operating)
        ops = confirmed_states(computed, np.isnan(engine), *self._n.confirm_args)
        # Downstream of the gate's own readings the believed OilTemp stands in for the raw.
        x = np.column_stack([oil if c == "OilTemp" else col(c) for c in COLUMNS])
        check, sensor = self._trackers.plausibility.series(x)
        check[silent] = STALE
        sensor[silent] = self._engine_col
        oor = self.validity.series(self.validity_values(rec, oil))
        oor[(ops != OpState.NORMAL) | (computed != OpState.NORMAL)] = -1
        return GateSeries(ops, check, sensor, oor, computed, oil)

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

    def beyond(self, g: GateSeries, inputs_ok: np.ndarray) -> np.ndarray:
        """Per sample, the believed OilTemp (degC) where the sample is gated for its OilTemp
        beyond the envelope and for nothing else, NaN elsewhere: where a statistic with an
        oil range of its own (``Statistic.beyond_oil``) may judge what J does not."""
        n = len(g.oor)
        k = self._oil_index
        if k < 0 or not self.gate_oor or g.oil_c is None:
            return np.full(n, np.nan)
        alone = (g.oor == k) & ~self.gated(dataclasses.replace(g, oor=np.full(n, -1)), inputs_ok)
        return np.where(alone, g.oil_c, np.nan)

    # -- live -----------------------------------------------------------------------------

    def step(self, row: np.ndarray) -> None:
        """One row ``[t, *columns]``: sets ``op_state``, ``check``/``sensor`` and ``oor``."""
        lay, tr = self._layout, self._trackers
        assert lay is not None, "a Gate for live rows is made with their columns"
        ext = lay.load(row)
        engine = float(ext[lay.engine])
        silent = tr.silence.step(engine, float(ext[lay.pp]), float(ext[lay.qp]))
        oil = tr.oil_belief.step(float(ext[lay.oil]))
        if lay.has_oil:
            ext[lay.oil] = oil  # the believed OilTemp for every check below
        self.computed = tr.op_state.step(self.min_engine_rpm if silent else engine, oil)
        op = OpState(tr.confirmer.step(self.computed, engine != engine))
        self.check = tr.plausibility.step(lay.ext, lay.plaus_idx)
        self.sensor = tr.plausibility.signal
        if silent:
            self.check, self.sensor = STALE, self._engine_col
        normal = op is OpState.NORMAL and self.computed is OpState.NORMAL
        self.oor = self.validity.check(ext, lay.val_idx) if normal else -1
        self.op_state = op
        self.oil_c = oil

    def gated_now(self, inputs_ok: bool) -> bool:
        return self._gated_but_for_range(inputs_ok) or (self.gate_oor and self.oor >= 0)

    def _gated_but_for_range(self, inputs_ok: bool) -> bool:
        return (
            self.op_state is not OpState.NORMAL
            or self.computed is not OpState.NORMAL
            or not inputs_ok
            or self.check != 0
        )

    def beyond_now(self, inputs_ok: bool) -> float:
        """``beyond`` for the last row: its believed OilTemp (degC) when it is gated for
        that alone, else NaN."""
        if self.oor < 0 or self.oor != self._oil_index or not self.gate_oor:
            return math.nan
        return math.nan if self._gated_but_for_range(inputs_ok) else self.oil_c

    def oor_name(self, oor: int) -> str | None:
        return self.validity.signals[oor] if oor >= 0 else None
