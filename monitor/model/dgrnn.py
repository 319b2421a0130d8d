"""The dynamic GRNN (He & He 2014, eqs. 5-7, 11): a GRNN over lagged, z-scored signals.

Data layout used throughout: a 2-D float64 array ``Z`` (rows = 100 Hz samples in time order,
columns = ``spec.variables`` = outputs first, then exogenous inputs), already z-scored with
the F0 (normal) statistics of :class:`Normalizer`.  NaN marks a missing sample.

Feature vector at time s: for each lag L in increasing order, for each variable with that lag
(in the order of ``spec.lags``), the value at s - L.  For the ``paper`` preset this is eq. 11
in the paper's order: [QP, PP, PA, PB](t-1), [QP, PP, PA, PB](t-2) -> QP(t).

Multi-step prediction (eq. 7) with horizon p: the prediction of y(t) starts from the measured
history up to k = t - p, predicts y(k+1), ..., y(t) in turn, and feeds each predicted output
back in place of the measured one; exogenous inputs are always the measured values.  p = 1 is
one-step-ahead prediction.  Outputs are never used at lag 0, so the measured output at t is
never an input to its own prediction.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.jit import jit, numba_loaded, pjit, prange
from monitor.model.grnn import GRNN
from monitor.model.grnn_core import n_chunks
from monitor.model.grnn_index import CutoffIndex, cutoff_row
from monitor.model.spec import DGRNNSpec

# --------------------------------------------------------------------------- embedding


def _check_data(spec: DGRNNSpec, Z: Any) -> np.ndarray:
    A = np.ascontiguousarray(np.asarray(Z, dtype=np.float64))
    if A.ndim != 2 or A.shape[1] != len(spec.variables):
        raise InputFileError(
            f"data must have {len(spec.variables)} columns ({', '.join(spec.variables)}),"
            f" got shape {A.shape}"
        )
    return A


def build_training_pairs(spec: DGRNNSpec, Z: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lag-embed z-scored data: X (pairs, features), Y (pairs, outputs), row index t.

    Training always uses measured values (the model learns the one-step map Gamma of eq. 6;
    the horizon only matters at prediction).  Rows whose window holds a NaN are skipped.
    """
    A = _check_data(spec, Z)
    n, L = A.shape[0], spec.max_lag
    fvar, flag = spec.feature_columns()
    if n <= L:
        raise InputFileError(f"{n} samples are too few for lags up to {L}: need at least {L + 1}")
    t = np.arange(L, n, dtype=np.int64)
    X = np.column_stack([A[L - lag : n - lag, v] for v, lag in zip(fvar, flag, strict=True)])
    Y = A[L:, : len(spec.outputs)]
    if spec.delta:
        mask = spec.delta_mask().astype(bool)
        Y = Y.copy()
        Y[:, mask] -= A[L - 1 : n - 1, : len(spec.outputs)][:, mask]
    ok = ~(np.isnan(X).any(axis=1) | np.isnan(Y).any(axis=1))
    return np.ascontiguousarray(X[ok]), np.ascontiguousarray(Y[ok]), t[ok]


# --------------------------------------------------------------------------- model


class DGRNN:
    """A fitted dynamic model: a spec plus a GRNN over its lag-embedded features."""

    def __init__(self, spec: DGRNNSpec, grnn: GRNN | None = None) -> None:
        self.spec = spec
        self.grnn = GRNN() if grnn is None else grnn

    def fit(self, data: Any | Sequence[Any]) -> DGRNN:
        """Fit on one z-scored array or a sequence of them (separate normal recordings).

        Recordings get disjoint time indices, more than ``exclude_neighbours`` apart, so the
        LOO bandwidth search never treats rows of different recordings as neighbours.
        """
        arrays = [data] if isinstance(data, np.ndarray) and data.ndim == 2 else list(data)
        if not arrays:
            raise InputFileError("no training data")
        m = int(self.grnn.exclude_neighbours)
        Xs, Ys, Ts, offset = [], [], [], 0
        for Z in arrays:
            X, Y, t = build_training_pairs(self.spec, Z)
            Xs.append(X)
            Ys.append(Y)
            Ts.append(t + offset)
            offset += len(Z) + m + 1
        X = np.concatenate(Xs)
        if X.shape[0] < 2:
            raise InputFileError(
                f"only {X.shape[0]} complete training window(s); need at least 2 rows without "
                f"missing samples over {self.spec.max_lag + 1} consecutive samples"
            )
        self.grnn.fit(X, np.concatenate(Ys), time_index=np.concatenate(Ts))
        return self

    def _fitted(self) -> GRNN:
        g = self.grnn
        if not hasattr(g, "patterns_"):
            raise ConfigError("this DGRNN is not fitted yet: call fit(data) first")
        if g.patterns_.shape[1] != len(self.spec.features) or g.targets_.shape[1] != len(
            self.spec.outputs
        ):
            raise ConfigError("the GRNN's pattern shape does not match the DGRNN spec")
        return g


@jit(aot=True)
def _predict_at(Z, t, tree, inv2s2, cut, fvar, flag, nout, p, delta, xbuf, pred, scratch, out):
    """Eq. 7: y_hat(t) from the measured history up to k = t - p; False if not predictable.

    ``pred`` (p, nout) holds y_hat(k+1..t); an output needed at row r > k is taken from it,
    every other input from the measured data.  Each step is one GRNN query on the index
    ``tree`` with cut-off ``cut`` (``monitor.model.grnn_index``; c = inf is brute force).
    """  # pragma: no cover - numba
    k = t - p
    nf = fvar.shape[0]
    for j in range(p):
        s = k + 1 + j
        for f in range(nf):
            v = fvar[f]
            r = s - flag[f]
            if v < nout and r > k:
                xbuf[f] = pred[r - k - 1, v]
            else:
                if r < 0:
                    return False
                val = Z[r, v]
                if np.isnan(val):
                    return False  # missing sample: prediction pauses, never guesses
                xbuf[f] = val
        cutoff_row(xbuf, tree, inv2s2, cut, scratch, pred[j])
        for i in range(nout):
            if delta[i]:  # the GRNN gave the change since s - 1; add the level it started from
                pred[j, i] += pred[j - 1, i] if j > 0 else Z[s - 1, i]
    for i in range(nout):
        out[i] = pred[p - 1, i]
    return True


@jit(aot=True)
def _predict_rows(Z, tree, inv2s2, cut, stack_len, fvar, flag, nout, p, delta, lo, hi, out):
    """``_predict_at`` for rows lo..hi-1 of ``out`` (left untouched where not predictable)."""
    npat = tree[0].shape[0]  # pragma: no cover - numba
    xbuf = np.empty(fvar.shape[0])
    pred = np.empty((p, nout))
    scratch = (np.empty(stack_len, np.int64), np.empty(npat), np.empty(npat, np.int64))
    for t in range(lo, hi):
        _predict_at(
            Z, t, tree, inv2s2, cut, fvar, flag, nout, p, delta, xbuf, pred, scratch, out[t]
        )


@pjit
def _predict_series(Z, tree, inv2s2, cut, stack_len, fvar, flag, nout, p, delta, nchunk):
    n = Z.shape[0]  # pragma: no cover - numba
    out = np.full((n, nout), np.nan)
    nchunk = max(1, min(n, nchunk))
    for c in prange(nchunk):
        _predict_rows(
            Z,
            tree,
            inv2s2,
            cut,
            stack_len,
            fvar,
            flag,
            nout,
            p,
            delta,
            c * n // nchunk,
            (c + 1) * n // nchunk,
            out,
        )
    return out


def _horizon(model: DGRNN, horizon: int | None) -> int:
    p = model.spec.horizon if horizon is None else int(horizon)
    if p < 1:
        raise ConfigError(f"horizon must be >= 1, got {horizon}")
    return p


def _index(model: DGRNN, exact: bool) -> tuple[GRNN, CutoffIndex]:
    g = model._fitted()
    return g, g.cutoff_index(exact)


def predict_series(
    model: DGRNN,
    data: Any,
    horizon: int | None = None,
    exact: bool = False,
    serial: bool = False,
) -> np.ndarray:
    """Offline: y_hat(t) for every row t of z-scored ``data`` (columns ``spec.variables``).

    Returns (rows, n_outputs), NaN where t is not predictable (too early for the lags and
    horizon, or a missing sample in the inputs it reads).  Parallel over t, unless
    ``serial`` or the kernel was compiled ahead of time and numba is not loaded (one
    thread, the same values: each row is computed alone).  By default
    each GRNN query sums only the patterns within the cut-off of ``monitor.model.grnn_index``
    (error <= 1e-6 of each output's std per step); ``exact=True`` sums every pattern.
    """
    g, index = _index(model, exact)
    Z = _check_data(model.spec, data)
    fvar, flag = model.spec.feature_columns()
    p = _horizon(model, horizon)
    nout = len(model.spec.outputs)
    args = (
        Z,
        index.tree,
        0.5 / g.sigma_**2,
        index.cut,
        index.scratch()[0].shape[0],
        fvar,
        flag,
        nout,
        p,
        model.spec.delta_mask(),
    )
    if serial or (not numba_loaded() and _predict_rows.runs_ahead_of_time):
        # One thread of ahead-of-time code (``monitor warm-up``): no numba, ~100 MB less.
        out = np.full((Z.shape[0], nout), np.nan)
        _predict_rows(*args, 0, Z.shape[0], out)
        return out
    return _predict_series(*args, n_chunks())


class TickPredictor:
    """Live path: predict the current sample from the last rows, with no allocation per tick.

    Queries use the cut-off index of ``monitor.model.grnn_index`` unless ``exact``.
    ``predict(window)`` takes the last ``rows_needed`` z-scored rows (columns
    ``spec.variables``, the last row being the current sample t, whose outputs are not read)
    and returns y_hat(t), or NaN when an input it reads is missing.  Pass float64 C-contiguous
    windows (e.g. a slice of the ring buffer): another layout compiles another kernel.
    """

    def __init__(self, model: DGRNN, horizon: int | None = None, exact: bool = False) -> None:
        g, self._index = _index(model, exact)
        self.model = model
        self.horizon = _horizon(model, horizon)
        self.rows_needed = model.spec.rows_needed(self.horizon)
        self._fvar, self._flag = model.spec.feature_columns()
        self._nout = len(model.spec.outputs)
        self._delta = model.spec.delta_mask()
        self._inv = 0.5 / g.sigma_**2
        self._xbuf = np.empty(self._fvar.shape[0])
        self._pred = np.empty((self.horizon, self._nout))
        self._scratch = self._index.scratch()
        self._out = np.empty(self._nout)

    def predict(self, window: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``out`` (n_outputs,) is filled and returned; by default an internal buffer that the
        next call overwrites."""
        o = self._out if out is None else out
        if window.ndim != 2 or window.shape[0] < self.rows_needed:
            raise InputFileError(
                f"a tick needs the last {self.rows_needed} rows, got shape {window.shape}"
            )
        if window.shape[1] != len(self.model.spec.variables):
            raise InputFileError(
                f"a tick row needs {len(self.model.spec.variables)} columns, got {window.shape[1]}"
            )
        ok = _predict_at(
            window,
            window.shape[0] - 1,
            self._index.tree,
            self._inv,
            self._index.cut,
            self._fvar,
            self._flag,
            self._nout,
            self.horizon,
            self._delta,
            self._xbuf,
            self._pred,
            self._scratch,
            o,
        )
        if not ok:
            o[:] = np.nan
        return o


def predict_tick(model: DGRNN, window: Any, horizon: int | None = None) -> np.ndarray:
    """One-off form of :class:`TickPredictor` (allocates; use the class in a loop)."""
    w = np.ascontiguousarray(np.asarray(window, dtype=np.float64))
    return TickPredictor(model, horizon).predict(w).copy()
