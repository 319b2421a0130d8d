"""The bias statistic B: small sustained residuals, beside the paper's J.

J (eq. 9) is the mean *squared* residual, so a small fault's steady offset adds little to
the scatter every duty cycle already has.  A worn seal or a stroke-limited spool moves the
*mean* of the residual in the operating regimes where it acts, and a mean over many samples
averages the scatter away.  B therefore keeps, over the last ``window_n`` valid samples, the
mean signed residual of every output in each of five spool regimes (hold; raising and
lowering at small and at large commands: a stroke limit only shows at large ones), turns
each into a standard score with the long-run standard deviation ``scale`` learnt from
held-out normal data, and averages the squared scores over the regimes seen often enough:

    z[r, o] = mean_r(e_o) * sqrt(n_r) / scale[r, o]      (n_r >= min_count samples in regime r)
    B       = mean over those r of (1/n_out) * sum_o z[r, o]^2

On normal data B is about 1 (a chi-square per degree of freedom); it grows with a fault's
offset squared and with the time the fault has been present.  Its threshold b0 comes from
held-out normal B by the same rule as eps0 from J (``monitor.model.threshold``).  Like J, B
is judged only on a full window: while the window fills, fewer regimes count, the average
over them is not diluted, and the first hold of a run read as a fault.

One step kernel (``_push``) serves the live ticker and the batch series, so both give the
same numbers.  A NaN residual (a gated or missing sample) pauses the window, as for J.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.jit import jit
from monitor.model.fields import fields_from_dict, fields_to_dict
from monitor.model.residual import resum_interval
from monitor.model.statistic import (
    HeldOut,
    Statistic,
    column,
    level_series,
    register,
    signal,
)
from monitor.model.threshold import MIN_BLOCKS

#: Spool command edges (%) of the regimes: |s| <= 5 hold; 5 < |s| <= 60 small; above: large.
HOLD_PCT = 5.0
LARGE_PCT = 60.0
N_BIAS_REGIMES = 5  # hold, raise small, raise large, lower small, lower large
REGIME_NAMES = ("hold", "raise_small", "raise_large", "lower_small", "lower_large")
#: Long-run standard deviation estimated by means of batches this long (samples of one regime).
BATCH = 500
#: A regime's scale is at least this share of the output's largest scale over the regimes: a
#: regime where the model is nearly exact (PB trapped at hold) would otherwise turn a
#: duty-cycle quirk the held-out data never showed into a huge score.
SCALE_FLOOR = 0.25


def bias_regime(spool_pct: float) -> int:
    """The regime of one sample (NaN counts as hold)."""
    a = abs(spool_pct)
    if not a > HOLD_PCT:
        return 0
    return (1 if spool_pct > 0 else 3) + (1 if a > LARGE_PCT else 0)


def bias_regimes(spool_pct: np.ndarray) -> np.ndarray:
    """``bias_regime`` for a whole series."""
    s = np.asarray(spool_pct, dtype=np.float64)
    a = np.abs(s)
    large = (a > LARGE_PCT).astype(np.int64)
    out = np.where(s > 0, 1, 3) + large
    return np.where(a > HOLD_PCT, out, 0).astype(np.int64)


@dataclass(frozen=True)
class BiasModel:
    """What the detector needs for B: window, the per-regime scales, threshold b0."""

    window_n: int  # samples (6000: 60 s at 100 Hz)
    min_count: int  # samples of a regime in the window before it counts
    scale: np.ndarray  # (N_BIAS_REGIMES, outputs), z-units x sqrt(samples)
    b0: float = float("nan")  # threshold; NaN: B is computed but never alarms

    def __post_init__(self) -> None:
        if self.window_n < 2 or not 1 <= self.min_count <= self.window_n:
            raise ConfigError(
                f"bias window {self.window_n} and min_count {self.min_count} must satisfy "
                "1 <= min_count <= window"
            )
        s = np.asarray(self.scale, dtype=np.float64)
        if s.ndim != 2 or s.shape[0] != N_BIAS_REGIMES or not np.all(np.isfinite(s) & (s > 0)):
            raise ConfigError(f"bias scale must be ({N_BIAS_REGIMES}, outputs), finite, positive")
        object.__setattr__(self, "scale", np.ascontiguousarray(s))

    def to_dict(self) -> dict[str, object]:
        return fields_to_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BiasModel:
        return fields_from_dict(cls, d)


def fit_scale(residuals: list[np.ndarray], regimes: list[np.ndarray]) -> np.ndarray:
    """Long-run standard deviation of the mean residual per regime and output, by batch means
    over held-out normal data (``BATCH`` consecutive samples of one regime per batch, so the
    residuals' autocorrelation is inside the batch).  A regime with fewer than three batches
    takes the output's largest scale; every scale is floored at ``SCALE_FLOOR`` of it."""
    n_out = residuals[0].shape[1]
    scale = np.full((N_BIAS_REGIMES, n_out), np.nan)
    for r in range(N_BIAS_REGIMES):
        means = []
        for e, reg in zip(residuals, regimes, strict=True):
            x = e[(reg == r) & np.isfinite(e).all(axis=1)]
            nb = len(x) // BATCH
            if nb:
                means.append(x[: nb * BATCH].reshape(nb, BATCH, n_out).mean(axis=1))
        if means and sum(len(m) for m in means) >= 3:
            scale[r] = np.std(np.concatenate(means), axis=0, ddof=1) * np.sqrt(BATCH)
    top = np.max(np.where(np.isfinite(scale), scale, -np.inf), axis=0)
    if not np.all(np.isfinite(top)) or not np.all(top > 0):
        raise InputFileError(
            "too little held-out normal data for the bias statistic: every output needs "
            f"3 batches of {BATCH} samples in some spool regime (give longer recordings)"
        )
    return np.maximum(np.where(np.isfinite(scale), scale, top), SCALE_FLOOR * top)


# State vector layout of the step kernel.
_POS, _COUNT, _PUSHES = 0, 1, 2


@jit(aot=True)
def _push(
    ring_e, ring_r, sums, counts, state, e, regime, scale, min_count, resum_every
):  # pragma: no cover - numba
    """One sample into the window; returns B (NaN: paused, the window not yet full, or no
    regime counted)."""
    n_out = e.shape[0]
    for o in range(n_out):
        if np.isnan(e[o]):
            return np.nan
    size = ring_r.shape[0]
    pos = state[_POS]
    if state[_COUNT] == size:  # full: the oldest sample leaves
        old = ring_r[pos]
        counts[old] -= 1.0
        for o in range(n_out):
            sums[old, o] -= ring_e[pos, o]
    else:
        state[_COUNT] += 1
    for o in range(n_out):
        ring_e[pos, o] = e[o]
        sums[regime, o] += e[o]
    ring_r[pos] = regime
    counts[regime] += 1.0
    state[_POS] = pos + 1 if pos + 1 < size else 0
    state[_PUSHES] += 1
    if state[_PUSHES] == resum_every:  # exact re-summation: add/subtract would drift
        state[_PUSHES] = 0
        sums[:, :] = 0.0
        for i in range(state[_COUNT]):
            for o in range(n_out):
                sums[ring_r[i], o] += ring_e[i, o]
    if state[_COUNT] < size:
        return np.nan
    total = 0.0
    used = 0
    for r in range(sums.shape[0]):
        k = counts[r]
        if k >= min_count:
            root = np.sqrt(k)
            for o in range(n_out):
                z = sums[r, o] / k * root / scale[r, o]
                total += z * z / n_out
            used += 1
    return total / used if used > 0 else np.nan


@jit(aot=True)
def _series(e, regimes, scale, window, min_count, resum_every):  # pragma: no cover - numba
    n, n_out = e.shape
    out = np.empty(n)
    ring_e = np.zeros((window, n_out))
    ring_r = np.zeros(window, dtype=np.int64)
    sums = np.zeros((scale.shape[0], n_out))
    counts = np.zeros(scale.shape[0])
    state = np.zeros(3, dtype=np.int64)
    for i in range(n):
        out[i] = _push(
            ring_e, ring_r, sums, counts, state, e[i], regimes[i], scale, min_count, resum_every
        )
    return out


def bias_series(e: np.ndarray, regimes: np.ndarray, bias: BiasModel) -> np.ndarray:
    """B at every sample of a series of residuals (samples, outputs) and their regimes."""
    a = np.ascontiguousarray(e, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != bias.scale.shape[1]:
        raise InputFileError(f"residuals {a.shape} do not fit the bias scale {bias.scale.shape}")
    r = np.ascontiguousarray(regimes, dtype=np.int64)
    return _series(a, r, bias.scale, bias.window_n, bias.min_count, resum_interval(bias.window_n))


class BiasWindow:
    """B kept up to date one tick at a time (the live ticker's; same kernel as the series)."""

    def __init__(self, bias: BiasModel, spool_col: int = -1) -> None:
        self.bias = bias
        self._spool_col = spool_col  # SpoolCmd in a sampler row (-1: none, always hold)
        n_out = bias.scale.shape[1]
        self._ring_e = np.zeros((bias.window_n, n_out))
        self._ring_r = np.zeros(bias.window_n, dtype=np.int64)
        self._sums = np.zeros((N_BIAS_REGIMES, n_out))
        self._counts = np.zeros(N_BIAS_REGIMES)
        self._state = np.zeros(3, dtype=np.int64)
        self._resum = resum_interval(bias.window_n)

    def push(self, e: np.ndarray, regime: int) -> float:
        """One sample's residuals (outputs) and bias regime; returns B."""
        b = self.bias
        return float(
            _push(
                self._ring_e,
                self._ring_r,
                self._sums,
                self._counts,
                self._state,
                e,
                regime,
                b.scale,
                b.min_count,
                self._resum,
            )
        )

    def step(self, e: np.ndarray, row: np.ndarray) -> float:
        """One sampler row's residuals; the regime from its SpoolCmd; returns B."""
        spool = float(row[self._spool_col]) if self._spool_col >= 0 else 0.0
        b = self.bias
        return float(
            _push(
                self._ring_e,
                self._ring_r,
                self._sums,
                self._counts,
                self._state,
                e,
                bias_regime(spool),
                b.scale,
                b.min_count,
                self._resum,
            )
        )


def alarm_level(
    j: np.ndarray,
    eps0: float,
    b: np.ndarray | None,
    bias: BiasModel | None,
    lever: tuple[np.ndarray, float] | None = None,
    hold: tuple[np.ndarray, float] | None = None,
) -> np.ndarray:
    """max(J / eps0, B / b0, L / l0, H / h0) from the series given, J / eps0 alone while the
    others are NaN or without them; NaN while J is.  The detector takes the level over every
    statistic of the family (``monitor.model.statistic.level_series``); this form names
    J, B, L and H for callers that hold their series apart."""
    pairs = [(j, eps0)]
    if b is not None and bias is not None:
        pairs.append((b, bias.b0))
    pairs += [p for p in (lever, hold) if p is not None]
    return level_series(pairs)


@register
class Bias(Statistic):
    """B as a member of the family: five spool regimes' mean residuals, standard scores."""

    name = "B"
    key = "bias"
    threshold_key = "b0"
    title = "bias statistic"
    colour = "tab:green"
    order = 1
    carries_over = True  # a standard score: a reference's b0 carries over to the type
    counts = ("window_n", "min_count")

    def __init__(self, window_n: int = 6000, min_count: int = 300) -> None:
        self.window_n_setting = window_n
        self.min_count = min_count

    @classmethod
    def configure(cls, settings: Any, outputs: tuple[str, ...], on: set[str]) -> Bias | str:
        if not settings.with_bias:
            return "off (--bias off, or the paper preset)"
        stats = settings.statistics
        return cls(stats.bias_window_n, stats.bias_min_count)

    def unscaled(self, held: HeldOut) -> BiasModel:
        if any(not r.has("SpoolCmd") for r in held.recordings):
            raise InputFileError("the held-out recordings have no SpoolCmd")
        judged = sum(int(np.isfinite(e).all(axis=1).sum()) for e in held.residuals)
        if judged < MIN_BLOCKS * self.window_n_setting:
            # Its threshold must rest on several of its own windows, not on one or two.
            raise InputFileError(
                f"{judged / 6000:.1f} min of held-out normal data; the bias statistic needs "
                f"{MIN_BLOCKS * self.window_n_setting / 6000:g} min ({MIN_BLOCKS} windows): "
                "give more with --held-out"
            )
        regimes = [bias_regimes(r["SpoolCmd"]) for r in held.recordings]
        scale = fit_scale(list(held.residuals), regimes)
        return BiasModel(self.window_n_setting, self.min_count, scale)

    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        return bias_series(e, bias_regimes(signal(rec, "SpoolCmd", 0.0)), self.params_)

    def window(self, columns: Sequence[str], n_out: int) -> BiasWindow:
        return BiasWindow(self.params_, column(columns, "SpoolCmd"))

    def coverage(self, held: HeldOut) -> dict[str, Any]:
        """Judged held-out samples per spool regime."""
        counts = np.zeros(N_BIAS_REGIMES, dtype=np.int64)
        for e, rec in zip(held.residuals, held.recordings, strict=True):
            ok = np.isfinite(e).all(axis=1)
            counts += np.bincount(bias_regimes(rec["SpoolCmd"])[ok], minlength=N_BIAS_REGIMES)
        return {"regime_samples": dict(zip(REGIME_NAMES, (int(c) for c in counts), strict=True))}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BiasModel:
        return BiasModel.from_dict(d)

    @classmethod
    def check_outputs(cls, params: BiasModel, n_out: int) -> None:
        if params.scale.shape[1] != n_out:
            raise ValueError(f"bias scale has {params.scale.shape[1]} outputs, the model {n_out}")
