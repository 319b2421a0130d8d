"""Model validity: the operating envelope the model was trained on, and samples outside it.

A GRNN only averages its training patterns, so away from them it predicts the nearest
trained behaviour, and the residual says "the machine is not where I was trained", not "the
hydraulics are worn".  The model file therefore keeps, per signal, the range it was trained
on and how densely that range was covered (an occupancy histogram of the training rows with
the engine running).

Only the operating-condition signals gate (``GATED``: spool and pump commands, engine speed,
oil temperature): they say where the machine is run.  A pressure or flow outside its trained
range is what a hydraulic fault looks like, so the ranges of PP, PA, PB and QP are kept and
reported but never hide a sample from the detector.

A sample is ``out_of_range`` when a gated signal lies beyond its trained [min, max] by more
than the margin: ``validity.margin_fraction`` of the trained span, and at least the
per-unit floor (``margin_pct``, ``margin_rpm``, ``margin_c``), which matters for a signal
that never moved in training (the simulator's engine runs at exactly 2200 rpm).  With
``validity.gate`` such samples are gated like engine-off ones: they seed no prediction and
their residual does not feed J (the window pauses); the alarm state is kept, the sample is
counted, and the event log says ``out_of_range``.

Model files written before the envelope existed (version 2 without it) still load: the
envelope is derived from the GRNN's patterns (cluster centroids, weighted by their counts),
which are slightly inside the training rows' range; the margin covers that.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from monitor.errors import ConfigError
from monitor.signals import COMMAND_NAMES, SIGNAL_NAMES, UNITS

if TYPE_CHECKING:
    from monitor.io.recording import Recording
    from monitor.model.modelfile import MonitorModel

#: Signals whose excursion gates detection (the operating conditions).
GATED: tuple[str, ...] = COMMAND_NAMES
BINS = 16  # occupancy histogram bins over each trained range


@dataclass(frozen=True)
class ValidityConfig:
    """``validity:`` section: how far beyond the trained range counts as out of range."""

    gate: bool = True  # out-of-range samples do not feed J (False: only counted and logged)
    margin_fraction: float = 0.05  # of the trained span (max - min)
    margin_pct: float = 5.0  # at least this for the commands (%)
    margin_rpm: float = 100.0  # at least this for EngineSpeed (rpm)
    margin_c: float = 5.0  # at least this for OilTemp (degC)
    #: A histogram bin holding less than this share of the training rows is "sparsely
    #: covered"; ``monitor detect`` reports the share of samples there per signal (not
    #: gated: the model may well generalise there, e.g. between trained oil temperatures).
    min_bin_share: float = 0.001

    def __post_init__(self) -> None:
        for name in ("margin_fraction", "margin_pct", "margin_rpm", "margin_c", "min_bin_share"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"validity.{name} must be >= 0")

    def floor(self, signal: str) -> float:
        return {"%": self.margin_pct, "rpm": self.margin_rpm, "degC": self.margin_c}.get(
            UNITS.get(signal, ""), 0.0
        )


@dataclass(frozen=True)
class Envelope:
    """Trained range and occupancy per signal (physical units)."""

    signals: tuple[str, ...]
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    occupancy: tuple[tuple[float, ...], ...]  # share of training rows per bin, BINS bins
    source: str  # "training" (rows of the training recordings) or "patterns" (derived)

    def to_dict(self) -> dict[str, Any]:
        return {
            "signals": list(self.signals),
            "min": list(self.lo),
            "max": list(self.hi),
            "occupancy": [list(o) for o in self.occupancy],
            "source": self.source,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Envelope:
        signals = tuple(str(s) for s in d["signals"])
        lo = tuple(float(v) for v in d["min"])
        hi = tuple(float(v) for v in d["max"])
        occ = tuple(tuple(float(v) for v in o) for o in d["occupancy"])
        if not len(signals) == len(lo) == len(hi) == len(occ):
            raise ValueError("envelope: signals, min, max and occupancy differ in length")
        if any(b < a for a, b in zip(lo, hi, strict=True)):
            raise ValueError("envelope: a max is below its min")
        return cls(signals, lo, hi, occ, str(d.get("source", "training")))

    def range_of(self, signal: str) -> tuple[float, float]:
        i = self.signals.index(signal)
        return self.lo[i], self.hi[i]


def _occupancy(x: np.ndarray, lo: float, hi: float, weights: np.ndarray | None) -> tuple:
    span = hi - lo
    edges = np.linspace(lo, hi if span > 0 else lo + 1.0, BINS + 1)
    counts, _ = np.histogram(x, bins=edges, weights=weights)
    total = counts.sum()
    return tuple(float(c / total) if total > 0 else 0.0 for c in counts)


def _from_columns(columns: dict[str, tuple[np.ndarray, np.ndarray | None]], source: str):
    names = [s for s in SIGNAL_NAMES if s in columns and columns[s][0].size]
    lo = tuple(float(np.min(columns[s][0])) for s in names)
    hi = tuple(float(np.max(columns[s][0])) for s in names)
    occ = tuple(
        _occupancy(columns[s][0], a, b, columns[s][1])
        for s, a, b in zip(names, lo, hi, strict=True)
    )
    return Envelope(tuple(names), lo, hi, occ, source)


def envelope_from_recordings(recordings: Sequence[Recording], min_engine_rpm: float) -> Envelope:
    """The envelope of training recordings: rows with the engine running, per signal the
    finite values."""
    cols: dict[str, list[np.ndarray]] = {}
    for rec in recordings:
        running = rec["EngineSpeed"] >= min_engine_rpm if rec.has("EngineSpeed") else None
        for s in SIGNAL_NAMES:
            if not rec.has(s):
                continue
            v = np.asarray(rec[s], dtype=np.float64)
            v = v[running] if running is not None else v
            cols.setdefault(s, []).append(v[np.isfinite(v)])
    return _from_columns({s: (np.concatenate(v), None) for s, v in cols.items()}, "training")


def envelope_from_patterns(model: MonitorModel) -> Envelope:
    """The envelope implied by the GRNN's patterns (for model files without one): per model
    variable its features at the smallest lag, back in physical units, weighted by counts."""
    spec, g = model.spec, model.dgrnn.grnn
    pats = np.asarray(g.patterns_)
    counts = np.asarray(g.counts_, dtype=np.float64)
    cols: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
    feats = spec.features
    for var in spec.variables:
        lags = [(lag, k) for k, (name, lag) in enumerate(feats) if name == var]
        if not lags:
            continue
        k = min(lags)[1]
        i = model.normalizer.names_.index(var)
        phys = pats[:, k] * model.normalizer.std_[i] + model.normalizer.mean_[i]
        cols[var] = (phys, counts)
    return _from_columns(cols, "patterns")


class Validity:
    """Out-of-range test per sample, the same comparisons offline and per tick."""

    def __init__(self, envelope: Envelope | None, cfg: ValidityConfig) -> None:
        self.envelope = envelope
        self.cfg = cfg
        names, lo, hi = [], [], []
        if envelope is not None:
            for s in GATED:
                if s in envelope.signals:
                    a, b = envelope.range_of(s)
                    m = max(cfg.margin_fraction * (b - a), cfg.floor(s))
                    names.append(s)
                    lo.append(a - m)
                    hi.append(b + m)
        self.signals: tuple[str, ...] = tuple(names)
        self.lo = np.array(lo, dtype=np.float64)
        self.hi = np.array(hi, dtype=np.float64)
        self._lo = tuple(lo)
        self._hi = tuple(hi)

    def series(self, values: np.ndarray) -> np.ndarray:
        """(samples, len(signals)) physical values -> index into ``signals`` of the first
        signal out of range per sample, -1 for none (NaN is never out of range)."""
        if not self.signals:
            return np.full(values.shape[0], -1, dtype=np.int8)
        bad = (values < self.lo) | (values > self.hi)
        first = np.argmax(bad, axis=1).astype(np.int8)
        first[~bad.any(axis=1)] = -1
        return first

    def check(self, row: np.ndarray, idx: tuple[int, ...]) -> int:
        """``series`` for one sample: ``row[idx[k]]`` is the value of ``signals[k]``."""
        for k in range(len(self._lo)):
            v = float(row[idx[k]])
            if v < self._lo[k] or v > self._hi[k]:
                return k
        return -1

    def sparse_shares(self, values: np.ndarray, mask: np.ndarray) -> dict[str, float]:
        """Per gated signal, the share of the ``mask``-ed samples that lie inside its trained
        range but in a histogram bin holding less than ``min_bin_share`` of the training
        rows (for the summary; only signals with such samples)."""
        env = self.envelope
        out: dict[str, float] = {}
        if env is None or not mask.any():
            return out
        for k, s in enumerate(self.signals):
            a, b = env.range_of(s)
            occ = np.asarray(env.occupancy[env.signals.index(s)])
            width = (b - a if b > a else 1.0) / BINS  # the edges of ``_occupancy``
            idx = np.floor((values[mask, k] - a) / width)
            inside = np.isfinite(idx) & (idx >= 0) & (idx <= BINS)
            bins = np.minimum(idx[inside], BINS - 1).astype(np.int64)  # max in the last bin
            share = float(np.sum(occ[bins] < self.cfg.min_bin_share)) / int(mask.sum())
            if share > 0:
                out[s] = round(share, 6)
        return out


def model_envelope(model: MonitorModel) -> Envelope:
    """The model's envelope; one derived from its patterns for a model built in memory
    without it (``load_model`` derives and logs it for files without one)."""
    return model.envelope if model.envelope is not None else envelope_from_patterns(model)
