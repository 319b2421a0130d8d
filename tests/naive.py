"""Plain-numpy / plain-Python references, written independently of the numba kernels.

Slow and obvious on purpose: every test compares a kernel to one of these.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from types import SimpleNamespace

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


def plausibility_findings(x, cfg, min_engine_rpm, period_s=0.01):
    """The sensor plausibility checks of monitor/detection/plausibility.py, written from its
    docstring sample by sample in plain Python (dicts of per-sensor state, no arrays).

    ``x``: rows of (SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp, PP, PA, PB, QP).
    Returns (check code, column) per sample: the first latched finding in check order
    (signal_range, frozen, stuck, pump_below_port, rest_offset = 1..5), then column order.
    """
    # The settings by their YAML keys (the config groups them in one record per check).
    cfg = SimpleNamespace(**{k: v for rec in asdict(cfg).values() for k, v in rec.items()})
    names = ["SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp", "PP", "PA", "PB", "QP"]
    dbc = {
        "SpoolCmd": (-100.0, 100.0),
        "PumpDispCmd": (0.0, 100.0),
        "EngineSpeed": (0.0, 3000.0),
        "OilTemp": (-40.0, 150.0),
    }
    lim = dict(dbc)
    for s in ("PP", "PA", "PB"):
        lim[s] = (cfg.pressure_min_bar, cfg.pressure_max_bar)
    lim["QP"] = (0.0, cfg.flow_max_lpm)
    samples = lambda sec: round(sec / period_s)  # noqa: E731
    sensors = ["PP", "PA", "PB", "QP"]
    checks = ["signal_range", "frozen", "stuck", "pump_below_port", "rest_offset"]
    latched = {(c, s): False for c in checks for s in names}
    out_of_range_run = {s: 0 for s in names}
    same_run = {s: 0 for s in sensors}
    previous = {s: None for s in sensors}
    anchor = {s: None for s in sensors}
    moving_in_band = {s: 0 for s in sensors}
    above_pump_run = {"PA": 0, "PB": 0}
    rest_run = 0
    result = []
    for row in x:
        v = dict(zip(names, (float(a) for a in row), strict=True))
        running = v["EngineSpeed"] >= min_engine_rpm  # False for NaN
        moving = running and (
            abs(v["SpoolCmd"]) >= cfg.move_spool_pct or v["QP"] >= cfg.move_flow_lpm
        )
        # The valve passes oil: open, the pump well above the port the command feeds; a
        # load-sensing pump stands its margin above a stalled section, so there the drop
        # must exceed the margin too.
        load_sensing = cfg.pump_system == "load_sensing"
        fed_name = "PA" if v["SpoolCmd"] > 0 else "PB"
        fed = v[fed_name]
        passing = (
            running
            and abs(v["SpoolCmd"]) >= cfg.relation_spool_pct
            and v["PP"] - fed
            > cfg.relation_margin_bar + (cfg.ls_margin_bar if load_sensing else 0.0)
        )
        for s in names:
            val = v[s]
            if math.isnan(val):
                continue
            lo, hi = lim[s]
            # A transducer may read a share of full scale below its range (offset, noise);
            # one at full scale is pinned there.
            in_range = (
                lo - cfg.range_tolerance_fs * (hi - lo) <= val < hi
                if s in sensors
                else lo <= val <= hi
            )
            if in_range:
                out_of_range_run[s] = 0
                latched[("signal_range", s)] = False
            else:
                out_of_range_run[s] += 1
                n = samples(cfg.range_s)
                if n > 0 and out_of_range_run[s] >= n:
                    latched[("signal_range", s)] = True
            if s not in sensors:
                continue
            # frozen: the very same value while the engine runs, strictly inside the range,
            # or a flow of exactly zero (its lower limit) while the valve passes oil
            if previous[s] is not None and val == previous[s]:
                if running and (lo < val < hi or (s == "QP" and val == lo and passing)):
                    same_run[s] += 1
                    n = samples(cfg.frozen_s)
                    if n > 0 and same_run[s] >= n:
                        latched[("frozen", s)] = True
            else:
                same_run[s] = 0
                latched[("frozen", s)] = False
            previous[s] = val
            # stuck: within a band of one value for stuck_s of moving time
            band = cfg.stuck_band_lpm if s == "QP" else cfg.stuck_band_bar
            if anchor[s] is None or abs(val - anchor[s]) > band:
                anchor[s] = val
                moving_in_band[s] = 0
                latched[("stuck", s)] = False
            elif moving:
                moving_in_band[s] += 1
                n = samples(cfg.stuck_s)
                if n > 0 and moving_in_band[s] >= n:
                    latched[("stuck", s)] = True
        # pump below a port while the spool is open
        n_rel = samples(cfg.relation_s)
        if (
            running
            and abs(v["SpoolCmd"]) >= cfg.relation_spool_pct
            and n_rel > 0
            and not math.isnan(v["PP"])
        ):
            # Load sensing: only the port the pump feeds is below it.
            for s in (fed_name,) if load_sensing else ("PA", "PB"):
                if v[s] > v["PP"] + cfg.relation_margin_bar:
                    above_pump_run[s] += 1
                    if above_pump_run[s] >= n_rel:
                        latched[("pump_below_port", s)] = True
                elif not math.isnan(v[s]):
                    above_pump_run[s] = 0
        latched[("pump_below_port", "PP")] = (
            latched[("pump_below_port", "PA")] and latched[("pump_below_port", "PB")]
        )
        # rest: engine off (a reading), spool centred, settled -> pressures at tank
        n_rest = samples(cfg.rest_settle_s)
        at_rest = (
            not math.isnan(v["EngineSpeed"])
            and not running
            and abs(v["SpoolCmd"]) < cfg.move_spool_pct
            and n_rest > 0
        )
        if at_rest:
            rest_run += 1
            if rest_run >= n_rest:
                for s in ("PP", "PA", "PB"):
                    if math.isnan(v[s]):
                        continue
                    at_tank = abs(v[s]) <= cfg.rest_max_bar
                    # The pump side and the rod side bleed to tank; the cap side may hold a
                    # parked boom's load, so it is never an offset at rest, only cleared.
                    latched[("rest_offset", s)] = not at_tank and s != "PA"
                    if at_tank:
                        latched[("pump_below_port", s)] = False
        else:
            rest_run = 0
        found = (0, -1)
        for k, c in enumerate(checks):
            hit = [i for i, s in enumerate(names) if latched[(c, s)]]
            if hit:
                found = (k + 1, hit[0])
                break
        result.append(found)
    return np.array([f[0] for f in result]), np.array([f[1] for f in result])


def poisson_rate_upper(events, hours, confidence=0.95):
    """Upper Poisson rate bound by bisection on the Poisson CDF (no scipy)."""
    k = np.arange(events + 1)
    log_fact = np.array([math.lgamma(i + 1.0) for i in k])

    def cdf(mu):
        return float(np.exp(-mu + k * math.log(mu) - log_fact).sum())

    lo, hi = 1e-12, 10.0 * (events + 10)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) > 1.0 - confidence else (lo, mid)
    return 0.5 * (lo + hi) / hours


def bias_statistic(e, regimes, scale, window, min_count):
    """The bias statistic B from its definition, recomputed from scratch at every sample: the
    last ``window`` samples whose residuals are all finite; per regime with at least
    ``min_count`` of them, z = mean * sqrt(count) / scale; B = mean over those regimes of the
    outputs' mean z^2.  NaN at a sample with a missing residual, before ``window`` valid
    samples have been seen, and before any regime counts."""
    e = np.asarray(e, dtype=float)
    n, n_out = e.shape
    out = np.full(n, np.nan)
    valid = []  # indices of the valid samples so far
    for i in range(n):
        if not all(math.isfinite(v) for v in e[i]):
            continue
        valid.append(i)
        if len(valid) < window:
            continue
        last = valid[-window:]
        terms = []
        for r in range(scale.shape[0]):
            members = [k for k in last if regimes[k] == r]
            if len(members) < min_count:
                continue
            total = 0.0
            for o in range(n_out):
                mean = sum(e[k, o] for k in members) / len(members)
                z = mean * math.sqrt(len(members)) / scale[r, o]
                total += z * z
            terms.append(total / n_out)
        if terms:
            out[i] = sum(terms) / len(terms)
    return out


def lever_statistic(e, spool_pct, output, scale, window, min_count, sign=0):
    """The full-lever statistic L from its definition, recomputed from scratch at every
    sample: direction 1 (raising) where SpoolCmd > 80 %, 2 (lowering) where < -80 %, else 0;
    the last ``window`` samples whose residuals are all finite; per direction d with at least
    ``min_count`` of them, v_d = |mean of e[:, output] over them| / scale[d - 1] (``sign``
    1: max(mean, 0) instead of |mean|, a shortfall only); L = the larger v_d.  NaN at a
    sample with a missing residual, before ``window`` valid samples have been seen, and where
    neither direction counts (a direction with an infinite scale never counts)."""
    e = np.asarray(e, dtype=float)
    out = np.full(len(e), np.nan)
    valid = []  # indices of the valid samples so far
    for i in range(len(e)):
        if not all(math.isfinite(v) for v in e[i]):
            continue
        valid.append(i)
        if len(valid) < window:
            continue
        last = valid[-window:]
        values = []
        for d in (1, 2):
            members = []
            for k in last:
                s = float(spool_pct[k])
                direction = 1 if s > 80.0 else 2 if s < -80.0 else 0
                if direction == d:
                    members.append(k)
            if len(members) < min_count or math.isinf(scale[d - 1]):
                continue
            mean = math.fsum(e[k, output] for k in members) / len(members)
            values.append((abs(mean) if sign == 0 else max(mean, 0.0)) / scale[d - 1])
        if values:
            out[i] = max(values)
    return out


def hold_statistic(e, spool_pct, outputs, scale, window, settle, min_count):
    """The hold statistic H from its definition, recomputed from scratch at every sample.

    A sample is valid when all its residuals are finite; an invalid one gives NaN.  A valid
    sample is a hold when |SpoolCmd| <= 5 % (NaN is not).  Its age is the number of
    consecutive valid hold samples ending with it, counting back until a non-hold sample or
    an invalid sample (0 for a non-hold sample); it counts when its age exceeds ``settle``.
    Over the last ``window`` valid samples, with n of them counted and n >= ``min_count``:
    H = max over k of |sum of e[:, outputs[k]] over the counted| / n / scale[k].  NaN before
    ``window`` valid samples have been seen, and while n < ``min_count``."""
    e = np.asarray(e, dtype=float)
    out = np.full(len(e), np.nan)
    counted = np.zeros(len(e), dtype=bool)
    valid = []
    for i in range(len(e)):
        if not all(math.isfinite(v) for v in e[i]):
            continue
        age = 0
        j = i
        while j >= 0 and all(math.isfinite(v) for v in e[j]) and abs(float(spool_pct[j])) <= 5.0:
            age += 1
            j -= 1
        counted[i] = age > settle
        valid.append(i)
        if len(valid) < window:
            continue
        members = [k for k in valid[-window:] if counted[k]]
        if len(members) < min_count:
            continue
        out[i] = max(
            abs(math.fsum(e[k, o] for k in members)) / len(members) / scale[q]
            for q, o in enumerate(outputs)
        )
    return out


def near_stop(
    spool_pct, qp_lpm, volume_up_l, volume_down_l, margin, q_stall_lpm, n_stall, period_s=0.01
):
    """The end-stop estimate from its definition, with the rod's possible places as a set.

    The rod's possible stroke fractions are kept as the pair (lowest, highest), both 0..1.
    A NaN command or flow: anywhere (0, 1).  A lever out (|SpoolCmd| > 5 %) with QP below
    ``q_stall_lpm`` for ``n_stall`` samples in a row: on the stop in the lever's direction
    (1 up, 0 down).  Otherwise a lever out moves both ends of the pair by the travel
    QP * period / 60 / volume (up for a positive command, down for a negative one) and cuts
    them at 0 and 1.  Returns 1 per sample where the pair comes within ``margin`` of an
    end (lowest < margin or highest > 1 - margin)."""
    low, high, run = 0.0, 1.0, 0
    out = []
    for s, q in zip(spool_pct, qp_lpm, strict=True):
        s, q = float(s), float(q)
        if math.isnan(s) or math.isnan(q):
            low, high, run = 0.0, 1.0, 0
        elif abs(s) > 5.0:
            run = run + 1 if q < q_stall_lpm else 0
            if run >= n_stall:
                low = high = 1.0 if s > 0 else 0.0
            else:
                up = s > 0
                travel = max(q, 0.0) * period_s / 60.0 / (volume_up_l if up else volume_down_l)
                if up:
                    low, high = min(1.0, low + travel), min(1.0, high + travel)
                else:
                    low, high = max(0.0, low - travel), max(0.0, high - travel)
        else:
            run = 0
        out.append(1 if low < margin or high > 1.0 - margin else 0)
    return np.array(out, dtype=np.int64)


def flow_statistic(
    spool_pct, rod_mm, qp_lpm, e, a, b, lo_mm, hi_mm, scale, count_n, beyond_c=None, oil=None
):
    """The flow-continuity statistic F from its definition, each sample's test re-read from
    the raw series (no rings, no running counts).

    A sample is judged when every residual of ``e`` (samples, outputs) is finite, or when
    ``beyond_c`` (the envelope gated it for its oil alone: that oil, NaN elsewhere) lies in
    ``oil`` (F's own range, lo..hi degC, both ends in).  A sample is valid when judged and
    its SpoolCmd, RodPos and QP are finite; an invalid one gives NaN.  Sample i counts when
    samples i-20..i are all valid, SpoolCmd < -20 % on i-10..i, v = (x[i] - x[i-10]) / 0.1
    < -10 mm/s, |v - (x[i-10] - x[i-20]) / 0.1| < 15 mm/s and x[i], x[i-10] are both more
    than 25 mm inside (lo, hi).  Its excess is the mean QP over i-9..i less a + b |v|.
    F = max(0, mean of the last ``count_n`` counted excesses) / scale, NaN until ``count_n``
    have counted; a valid sample that does not count keeps the F of the last that did."""
    spool, rod, qp = (np.asarray(x, dtype=float) for x in (spool_pct, rod_mm, qp_lpm))
    n = len(spool)
    warm = [math.nan] * n if beyond_c is None else list(beyond_c)
    judged = [
        all(math.isfinite(x) for x in e[i])
        or (oil is not None and math.isfinite(warm[i]) and oil[0] <= warm[i] <= oil[1])
        for i in range(n)
    ]
    valid = [
        judged[i] and all(math.isfinite(x) for x in (spool[i], rod[i], qp[i])) for i in range(n)
    ]
    excesses: list[float] = []
    last = math.nan
    out = np.full(n, np.nan)
    for i in range(n):
        if not valid[i]:
            continue
        if i >= 20 and all(valid[i - 20 : i + 1]) and all(s < -20.0 for s in spool[i - 10 : i + 1]):
            v = (rod[i] - rod[i - 10]) / 0.1
            before = (rod[i - 10] - rod[i - 20]) / 0.1
            inside = all(lo_mm + 25.0 < x < hi_mm - 25.0 for x in (rod[i], rod[i - 10]))
            if v < -10.0 and abs(v - before) < 15.0 and inside:
                excesses.append(math.fsum(qp[i - 9 : i + 1]) / 10.0 - (a + b * abs(v)))
                if len(excesses) >= count_n:
                    last = max(math.fsum(excesses[-count_n:]) / count_n, 0.0) / scale
        out[i] = last
    return out
