"""Residuals and the windowed mean squared residual J (He & He 2014, eqs. 8-9).

    e = y_hat - y                                                  (eq. 8)
    J(k+1) = 1/(N+1) * sum_{i=k+1-N}^{k+1} e^2(i)                  (eq. 9)

The window holds N + 1 samples (i runs from k+1-N to k+1 inclusive).

Several outputs: e^2(i) is the mean of the squared residuals of the outputs at sample i
(all in z-score units), so with one output this is eq. 9 exactly and with several J keeps
the same scale as a single output's J.

Missing data: a sample whose residual has a NaN in any output is not pushed into the window
(the window *pauses*): J is reported as NaN at that sample (no verdict without data; the
detector marks a sensor fault), and when data returns the window continues with the N + 1
most recent valid samples.  Before N + 1 valid samples have been seen, J is NaN (warm-up).
Call :meth:`WindowJ.reset` to forget the window (e.g. after a long gap).

The incremental form keeps a running sum, O(1) per tick; every ``resum_every`` pushes the
sum is recomputed exactly from the ring so float drift cannot accumulate.  The batch form
runs the same algorithm in numba, so both give the same numbers (to rounding).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.jit import jit
from monitor.model.filecheck import MAX_WINDOW_N, check_number
from monitor.model.statistic import HeldOut, Statistic, column, register, signal


def residuals(y_hat: Any, y: Any) -> np.ndarray:
    """Eq. 8: e = y_hat - y, elementwise (NaN where either is missing)."""
    a = np.asarray(y_hat, dtype=np.float64)
    b = np.asarray(y, dtype=np.float64)
    if a.shape != b.shape:
        raise InputFileError(f"predictions {a.shape} and measurements {b.shape} differ in shape")
    return a - b


def largest_finite(series: Iterable[np.ndarray]) -> float:
    """The largest finite value over several series of a statistic (0.0 when none has one):
    the held-out maximum a statistic's scale is fitted to."""
    top = 0.0
    for s in series:
        if np.isfinite(s).any():
            top = max(top, float(np.nanmax(s)))
    return top


def squared_residual(e: Any) -> np.ndarray:
    """e^2 per sample, averaged over outputs (columns); NaN if any output is NaN."""
    a = np.asarray(e, dtype=np.float64)
    if a.ndim == 1:
        return a * a
    if a.ndim != 2:
        raise InputFileError(f"residuals must be 1-D or (samples, outputs), got {a.shape}")
    return np.mean(a * a, axis=1)


def _check_window(N: int) -> int:
    n = int(N)
    if n < 0:
        raise ConfigError(f"the J window length N must be >= 0, got {N}")
    return n


def resum_interval(window: int) -> int:
    """Pushes between exact re-summations of a running window sum of ``window`` samples:
    add/subtract drifts in floating point, a full re-sum now and then does not."""
    return max(1000, 10 * window)


def _default_resum(N: int) -> int:
    return resum_interval(N + 1)


@jit(aot=True)
def _j_series(s, size, resum_every):  # pragma: no cover - numba
    n = s.shape[0]
    out = np.full(n, np.nan)
    ring = np.zeros(size)
    pos = 0
    count = 0
    pushes = 0
    total = 0.0
    for i in range(n):
        v = s[i]
        if np.isnan(v):
            continue
        total += v - ring[pos]
        ring[pos] = v
        pos += 1
        if pos == size:
            pos = 0
        if count < size:
            count += 1
        pushes += 1
        if pushes == resum_every:
            pushes = 0
            total = 0.0
            for j in range(size):
                total += ring[j]
        if count == size:
            out[i] = total / size
    return out


def window_j(e: Any, N: int, resum_every: int | None = None) -> np.ndarray:
    """Eq. 9 for a whole series: J at every sample (NaN during warm-up and at missing samples).

    ``e`` is (samples,) or (samples, outputs) residuals.
    """
    n = _check_window(N)
    s = np.ascontiguousarray(squared_residual(e))
    every = _default_resum(n) if resum_every is None else int(resum_every)
    if every < 1:
        raise ConfigError("resum_every must be >= 1")
    return _j_series(s, n + 1, every)


class WindowJ:
    """Eq. 9 kept up to date one tick at a time (fixed ring, no allocation per tick)."""

    def __init__(self, N: int, resum_every: int | None = None) -> None:
        self.N = _check_window(N)
        self.size = self.N + 1
        self.resum_every = _default_resum(self.N) if resum_every is None else int(resum_every)
        if self.resum_every < 1:
            raise ConfigError("resum_every must be >= 1")
        self._ring = np.zeros(self.size)
        self.reset()

    def reset(self) -> None:
        """Forget every sample: J is NaN until N + 1 new valid samples have arrived."""
        self._ring[:] = 0.0
        self._pos = 0
        self._count = 0
        self._pushes = 0
        self._total = 0.0
        self.value = float("nan")  # last J computed (held through missing samples)

    @property
    def ready(self) -> bool:
        """True once the window is full (J is defined)."""
        return self._count == self.size

    def update(self, e: Any) -> float:
        """Push one sample's residual (a float or the outputs' residuals); return J.

        NaN (a missing sample) pauses the window and returns NaN; ``value`` keeps the last J.
        """
        if isinstance(e, float):
            v = e * e
        else:
            a = np.asarray(e, dtype=np.float64)
            v = float(np.dot(a.ravel(), a.ravel())) / a.size
        return self.push_squared(v)

    def push_squared(self, v: float) -> float:
        """Push an already squared (and output-averaged) residual e^2; see :meth:`update`."""
        if v != v:  # NaN
            return float("nan")
        ring = self._ring
        self._total += v - ring[self._pos]
        ring[self._pos] = v
        self._pos += 1
        if self._pos == self.size:
            self._pos = 0
        if self._count < self.size:
            self._count += 1
        self._pushes += 1
        if self._pushes == self.resum_every:
            # Exact re-summation: the running add/subtract would otherwise drift.
            self._pushes = 0
            self._total = float(ring.sum())
        if self._count < self.size:
            return float("nan")
        self.value = self._total / self.size
        return self.value


@dataclass(frozen=True)
class JModel:
    """What J keeps in the model file: its window N, J0 and the threshold eps0 (eq. 10), and
    whether J leaves out the samples settling on an end stop (``stops``; a file from before
    it has none: False, J over every sample as before)."""

    window_n: int
    j0: float
    eps0: float
    stops: bool = False


def on_stops(rec: Recording) -> np.ndarray:
    """The samples of ``rec`` settling on an end stop (``endstop.settling_on_stop``); none
    for a recording without SpoolCmd or QP."""
    from monitor.model.endstop import settling_on_stop  # endstop -> bias -> this module

    return settling_on_stop(signal(rec, "SpoolCmd", 0.0), signal(rec, "QP", math.nan))


def leave_out_stops(e: np.ndarray, rec: Recording) -> np.ndarray:
    """``e`` with the rows settling on an end stop set to NaN: J's window pauses there and
    those samples are not judged (never healthy)."""
    out = np.array(e, dtype=np.float64, copy=True)
    out[on_stops(rec)] = np.nan
    return out


class _JWindow:
    """J over sampler rows: e^2 averaged over outputs as ``squared_residual`` does (one row
    reduced by numpy, so live and batch round alike), then eq. 9's running window; with
    ``stops`` (the rows' SpoolCmd and QP columns), a row settling on an end stop pauses it."""

    def __init__(self, window_n: int, n_out: int, stops: tuple[int, int] | None = None) -> None:
        self._sq = np.empty((1, n_out))
        self._v = np.empty(1)
        self._window = WindowJ(window_n)
        from monitor.model.endstop import SettleTracker  # endstop -> bias -> this module

        self._stops = stops
        self._settle = SettleTracker()

    def step(self, e: np.ndarray, row: np.ndarray) -> float:
        if self._stops is not None:
            spool, qp = self._stops
            if self._settle.push(float(row[spool]), float(row[qp])):
                return math.nan
        np.multiply(e, e, out=self._sq[0])
        np.mean(self._sq, axis=1, out=self._v)
        return self._window.push_squared(float(self._v[0]))


#: The model file's header key (and ``MonitorModel.statistics`` key) saying that J leaves out
#: the samples settling on an end stop.
STOPS_KEY = "j_leaves_out_stops"


@register
class J(Statistic):
    """The paper's windowed mean squared residual, eq. 9: the level rests on it (NaN while
    its window warms up or pauses), the others only raise it.  Its file keys are the
    header's own (``window_n``, ``j0``, ``eps0``), as before the family existed."""

    name = "J"
    key = "j"
    threshold_key = "eps0"
    title = "J"
    colour = "k"
    unit = " z^2"
    order = 0
    carries_over = True
    optional = False

    def __init__(self, window_n: int = 3000, stops: bool = False) -> None:
        self.window_n_setting = window_n
        self.stops_setting = stops

    @classmethod
    def configure(cls, settings: Any, outputs: tuple[str, ...], on: set[str]) -> J | str:
        return cls(settings.statistics.window_n, settings.statistics.j_leaves_out_stops)

    def unscaled(self, held: HeldOut) -> JModel:
        window = _check_window(self.window_n_setting)
        return JModel(window, math.nan, math.nan, bool(self.stops_setting))

    def with_threshold(self, threshold: float, reference: float | None = None) -> JModel:
        j0 = self.params_.j0 if reference is None else reference  # J0 (eq. 10)
        return JModel(self.params_.window_n, j0, threshold, self.params_.stops)

    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        return window_j(leave_out_stops(e, rec) if self.params_.stops else e, self.window_n)

    def window(self, columns: Sequence[str], n_out: int) -> _JWindow:
        spool, qp = column(columns, "SpoolCmd"), column(columns, "QP")
        use = self.params_.stops and spool >= 0 and qp >= 0
        return _JWindow(self.window_n, n_out, (spool, qp) if use else None)

    @classmethod
    def summary_keys(cls) -> tuple[str, str]:
        return "max_J", "threshold"  # the contract's names, from before the family

    def summary(self, series: np.ndarray | None) -> dict[str, Any]:
        return super().summary(series) | {"J0": float(self.params_.j0)}

    @classmethod
    def absent(cls) -> dict[str, Any]:
        return super().absent() | {"J0": None}

    @classmethod
    def known_support(cls, training: dict[str, Any]) -> dict[str, Any]:
        out = super().known_support(training)
        if training.get("threshold_one_event"):
            out["one_event"] = training["threshold_one_event"]  # J0 rests on one event
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> JModel:
        stops = bool(d.get(STOPS_KEY, False))  # absent: a file from before, J over every sample
        return JModel(int(d["window_n"]), float(d["j0"]), float(d["eps0"]), stops)

    @classmethod
    def get(cls, model: Any) -> JModel:
        stops = bool(model.statistics.get(STOPS_KEY, False))
        return JModel(int(model.window_n), float(model.j0), float(model.eps0), stops)

    @classmethod
    def put(cls, model: Any, params: JModel) -> None:
        model.window_n, model.j0, model.eps0 = params.window_n, params.j0, params.eps0
        if params.stops:
            model.statistics[STOPS_KEY] = True
        else:
            model.statistics.pop(STOPS_KEY, None)

    @classmethod
    def write(cls, header: dict[str, Any], params: JModel) -> None:
        header.update(window_n=int(params.window_n), j0=float(params.j0), eps0=float(params.eps0))
        if params.stops:  # written only when set: a file without it reads as before
            header[STOPS_KEY] = True

    @classmethod
    def read(cls, header: dict[str, Any], n_out: int) -> JModel:
        return cls.from_dict(header)

    @classmethod
    def check_header(cls, header: dict[str, Any]) -> None:
        window = header.get("window_n")
        if (
            isinstance(window, bool)
            or not isinstance(window, int)
            or not (1 <= window <= MAX_WINDOW_N)
        ):
            raise ValueError(
                f"header window_n must be a whole number 1..{MAX_WINDOW_N}, got {str(window)[:40]}"
            )
        check_number(header, "j0", 0.0, strict=False)
        check_number(header, "eps0", 0.0, strict=True)
        if not isinstance(header.get(STOPS_KEY, False), bool):
            raise ValueError(f"header {STOPS_KEY} must be true or false")
