"""Plain-numpy / plain-Python references, written independently of the numba kernels.

Slow and obvious on purpose: every test compares a kernel to one of these.
"""

from __future__ import annotations

import math

import numpy as np


def grnn_predict(X, P, Y, sigma):
    """Eq. 4 with the same min-distance shift as the kernel (so far queries stay finite)."""
    X = np.atleast_2d(np.asarray(X, float))
    P = np.asarray(P, float)
    Y = np.asarray(Y, float).reshape(len(P), -1)
    D = ((X[:, None, :] - P[None, :, :]) ** 2).sum(axis=2) / (2.0 * sigma**2)
    W = np.exp(-(D - D.min(axis=1, keepdims=True)))
    return (W @ Y) / W.sum(axis=1, keepdims=True)


def grnn_predict_unshifted(X, P, Y, sigma):
    """Eq. 4 literally (underflows to 0/0 = NaN for far-away queries)."""
    X = np.atleast_2d(np.asarray(X, float))
    P = np.asarray(P, float)
    Y = np.asarray(Y, float).reshape(len(P), -1)
    D = ((X[:, None, :] - P[None, :, :]) ** 2).sum(axis=2) / (2.0 * sigma**2)
    W = np.exp(-D)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (W @ Y) / W.sum(axis=1, keepdims=True)


def loo_errors(Q, Qy, qidx, P, Py, pidx, sigma, m):
    """Per query: mean over outputs of the squared error of eq. 4 over patterns > m away."""
    Q, P = np.asarray(Q, float), np.asarray(P, float)
    Qy = np.asarray(Qy, float).reshape(len(Q), -1)
    Py = np.asarray(Py, float).reshape(len(P), -1)
    out = np.full(len(Q), np.nan)
    for q in range(len(Q)):
        keep = np.abs(np.asarray(pidx) - qidx[q]) > m
        if not keep.any():
            continue
        pred = grnn_predict(Q[q], P[keep], Py[keep], sigma)[0]
        out[q] = np.mean((pred - Qy[q]) ** 2)
    return out


def grnn_predict_counts(X, P, Y, counts, sigma):
    """Specht's clustered form: sum c_i y_i exp(-d_i) / sum c_i exp(-d_i), in log space."""
    X = np.atleast_2d(np.asarray(X, float))
    P = np.asarray(P, float)
    Y = np.asarray(Y, float).reshape(len(P), -1)
    D = ((X[:, None, :] - P[None, :, :]) ** 2).sum(axis=2) / (2.0 * sigma**2)
    L = np.log(np.asarray(counts, float))[None, :] - D
    W = np.exp(L - L.max(axis=1, keepdims=True))
    return (W @ Y) / W.sum(axis=1, keepdims=True)


def cluster_loo_errors(rows, X, Y, tidx, assign, sigma, m):
    """Per query row: rebuild every cluster (mean input, mean target, count) from its
    members more than m samples away in time, then predict with the clustered form (NaN
    when no cluster is left)."""
    X = np.asarray(X, float)
    Y = np.asarray(Y, float).reshape(len(X), -1)
    tidx, assign = np.asarray(tidx), np.asarray(assign)
    out = np.full(len(rows), np.nan)
    for n, r in enumerate(rows):
        far = (np.abs(tidx - tidx[r]) > m) & (assign >= 0)
        labels = np.unique(assign[far])
        if not len(labels):
            continue
        members = [far & (assign == i) for i in labels]
        P = np.array([X[k].mean(axis=0) for k in members])
        means = np.array([Y[k].mean(axis=0) for k in members])
        counts = np.array([k.sum() for k in members], float)
        pred = grnn_predict_counts(X[r], P, means, counts, sigma)[0]
        out[n] = np.mean((pred - Y[r]) ** 2)
    return out


def thin_min_distance(X, r):
    """Greedy: keep a row if its distance to every kept row is > r."""
    kept = []
    for i, x in enumerate(np.asarray(X, float)):
        if all(math.dist(x, X[j]) > r for j in kept):
            kept.append(i)
    return np.array(kept, dtype=int)


def embed(spec, Z):
    """Lag embedding row by row; rows with a NaN in the window skipped."""
    cols = {name: i for i, name in enumerate(spec.variables)}
    nout = len(spec.outputs)
    X, Y, T = [], [], []
    for t in range(spec.max_lag, len(Z)):
        x = [Z[t - lag][cols[name]] for name, lag in spec.features]
        y = list(Z[t][:nout])
        for i, name in enumerate(spec.outputs):  # delta outputs: changes since t - 1
            if name in spec.delta:
                y[i] = y[i] - Z[t - 1][i]
        if any(math.isnan(v) for v in x + y):
            continue
        X.append(x)
        Y.append(y)
        T.append(t)
    return np.array(X), np.array(Y), np.array(T, dtype=int)


def multistep(spec, Z, P, Y, sigma, p, counts=None):
    """Eq. 7 by hand: for each t, run p one-step predictions from k = t - p."""
    counts = np.ones(len(P)) if counts is None else counts
    cols = {name: i for i, name in enumerate(spec.variables)}
    nout = len(spec.outputs)
    out = np.full((len(Z), nout), np.nan)
    for t in range(len(Z)):
        k = t - p
        preds = {}  # row -> predicted outputs
        ok = True
        for s in range(k + 1, t + 1):
            x = []
            for name, lag in spec.features:
                r = s - lag
                if name in spec.outputs and r > k:
                    x.append(preds[r][cols[name]])
                elif r < 0 or math.isnan(Z[r][cols[name]]):
                    ok = False
                    break
                else:
                    x.append(Z[r][cols[name]])
            if not ok:
                break
            preds[s] = grnn_predict_counts(np.array(x), P, Y, counts, sigma)[0]
            for i, name in enumerate(spec.outputs):  # delta outputs: add the level before
                if name in spec.delta:
                    preds[s][i] += preds[s - 1][i] if s - 1 > k else Z[s - 1][i]
        if ok:
            out[t] = preds[t]
    return out


def window_j(s, N):
    """Eq. 9 over the N+1 most recent valid e^2 values; NaN at missing samples and warm-up."""
    window = []
    out = []
    for v in s:
        if math.isnan(v):
            out.append(math.nan)
            continue
        window.append(v)
        if len(window) > N + 1:
            window.pop(0)
        out.append(math.fsum(window) / (N + 1) if len(window) == N + 1 else math.nan)
    return np.array(out)


def crc8_bitwise(data: bytes) -> int:
    """Textbook bit-by-bit CRC-8/SAE-J1850, independent of the code under test."""
    reg = 0xFF
    for byte in data:
        reg ^= byte
        for _ in range(8):
            reg = ((reg << 1) ^ 0x1D) & 0xFF if reg & 0x80 else (reg << 1) & 0xFF
    return reg ^ 0xFF
