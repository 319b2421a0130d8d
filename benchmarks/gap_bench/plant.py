"""An independent boom-loop plant for the withheld-effect benchmark.

Written apart from ``monitor.sim`` on purpose, with formulations that differ from the
simulator's own where the physics allows a choice, so that a diagnosis that only
recognises its own simulator's fingerprints fails:

- entrained air: a two-phase mixture compressibility (oil and isothermal/polytropic air
  volumes in series), not Simscape's formula;
- friction: LuGre (bristle state z, Canudas de Wit et al. 1995), not static Stribeck;
- spool: second order with a spool velocity limit;
- pump control: a rate-limited first-order displacement servo;
- oil viscosity: an Arrhenius-type (exponential) viscosity-temperature law, not Walther;
- load variation: a nonlinear (quadratic) lever geometry, not a linear slope;
- sensors: a second-order (Butterworth-like) filter plus a delay, not first order;
- out of the catalogue: a periodic load disturbance, a partly blocked return line and
  cross-port leakage across the piston.

SI inside.  Fixed-step RK4 at 200 us, numba.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.signal import bilinear, lfilter

# Parameter vector indices.
(
    BETA,
    VL,
    V0A,
    V0B,
    AA,
    AB,
    STROKE,
    MASS,
    FG,
    CV,
    KV,
    DPL,
    DMAX,
    CS,
    CF,
    RC,
    RG,
    AIR,
    AIRN,
    LUGRE,
    FC,
    FS,
    VS,
    SIG0,
    SIG1,
    SPOOL,
    WN,
    ZETA,
    SVMAX,
    OVL,
    PTAU,
    PRATE,
    EWALL,
    LEAK,
    K1,
    K2,
    XREF,
    PAMP,
    PFREQ,
    KRET,
    XLEAK,
) = range(41)
N_P = 41
NS = 9  # pp, pa, pb, x, v, xs, vs, disp, z
P_ATM = 101325.0


def nominal(tol: dict[str, float] | None = None) -> np.ndarray:
    """The reference machine (docs/reference/contracts.md), optional multiplicative tolerances."""
    t = {
        "mass": 1.0,
        "gravity": 1.0,
        "friction": 1.0,
        "valve": 1.0,
        "vol_a": 1.0,
        "vol_b": 1.0,
        "vol_line": 1.0,
        **(tol or {}),
    }
    p = np.zeros(N_P)
    p[BETA] = 1.5e9
    p[VL] = 0.5e-3 * t["vol_line"]
    p[V0A] = 0.3e-3 * t["vol_a"]
    p[V0B] = 0.3e-3 * t["vol_b"]
    p[AA] = math.pi / 4 * 0.063**2
    p[AB] = math.pi / 4 * (0.063**2 - 0.036**2)
    p[STROKE] = 0.5
    p[MASS] = 400.0 * t["mass"]
    p[FG] = 6000.0 * t["gravity"]
    p[CV] = 2000.0 * t["friction"]
    p[KV] = 20.0 / 60000.0 / math.sqrt(10e5) * t["valve"]
    p[DPL] = 0.3e5
    p[DMAX] = 11e-6
    p[CS], p[CF] = 190e5, 200e5
    p[RC] = 210e5
    p[RG] = 11e-6 * 2200 / 60 / 10e5
    p[AIRN] = 1.4
    p[WN], p[ZETA], p[SVMAX] = 1.0, 1.0, 1e9
    p[PTAU], p[PRATE] = 0.0, 1e9
    p[XREF] = 0.25
    p[SIG0], p[SIG1], p[VS] = 1e6, 1000.0, 0.01
    return p


@njit(cache=True)
def _flow(k: float, dp: float, dpl: float) -> float:
    return k * dp / math.sqrt(math.sqrt(dp * dp + dpl * dpl))


@njit(cache=True)
def _cap(p: float, vol: float, hose: float, q: np.ndarray) -> float:
    """dV/dp of a node: oil, plus air as a separate polytropic gas volume, plus hose walls."""
    c = vol / q[BETA]
    if q[AIR] > 0.0:
        pabs = max(p + P_ATM, 2e3)
        n = q[AIRN]
        v_air = q[AIR] * vol * (P_ATM / pabs) ** (1.0 / n)
        c += v_air / (n * pabs)
    if q[EWALL] > 0.0:
        c += hose / q[EWALL]
    return c


@njit(cache=True)
def _rhs(y, u, t, q, dy):
    pp, pa, pb = max(y[0], 0.0), max(y[1], 0.0), max(y[2], 0.0)
    x, v = y[3], y[4]
    if q[SPOOL] > 0.0:
        xs = y[5]
        acc = q[WN] * q[WN] * (u[0] - xs) - 2.0 * q[ZETA] * q[WN] * y[6]
        vs = y[6]
        if (vs >= q[SVMAX] and acc > 0.0) or (vs <= -q[SVMAX] and acc < 0.0):
            acc = 0.0
        dy[5], dy[6] = vs, acc
    else:
        xs = u[0]
        dy[5] = dy[6] = 0.0
    mag = max(abs(xs) - q[OVL], 0.0) / (1.0 - q[OVL])
    o_pos = mag if xs > 0.0 else 0.0
    o_neg = mag if xs < 0.0 else 0.0
    kv = q[KV]
    q_pa = _flow(kv * o_pos, pp - pa, q[DPL])
    q_pb = _flow(kv * o_neg, pp - pb, q[DPL])
    # Return edges, optionally in series with a restriction (a partly blocked return line).
    kb, ka = kv * o_pos, kv * o_neg
    if q[KRET] > 0.0:
        kr = q[KRET]
        kb = kb * kr / math.sqrt(kb * kb + kr * kr) if kb > 0.0 else 0.0
        ka = ka * kr / math.sqrt(ka * ka + kr * kr) if ka > 0.0 else 0.0
    q_bt = _flow(kb, pb, q[DPL])
    q_at = _flow(ka, pa, q[DPL])
    q_x = q[XLEAK] * (pa - pb)

    comp = min(max((q[CF] - pp) / (q[CF] - q[CS]), 0.0), 1.0)
    target = u[1] * comp
    if q[PTAU] > 0.0:
        rate = (target - y[7]) / q[PTAU]
        rate = min(max(rate, -q[PRATE]), q[PRATE])
        disp, dy[7] = y[7], rate
    else:
        disp, dy[7] = target, 0.0
    qp = disp * q[DMAX] * u[2] - q[LEAK] * pp / u[3]
    q_rel = q[RG] * max(pp - q[RC], 0.0)
    dy[0] = (qp - q_rel - q_pa - q_pb) / _cap(pp, q[VL], q[VL], q)

    dxr = x - q[XREF]
    f_load = q[FG] + q[K1] * dxr + q[K2] * dxr * dxr
    if q[PAMP] > 0.0:
        f_load += q[PAMP] * math.sin(2.0 * math.pi * q[PFREQ] * t)
    f_fric = q[CV] * v
    if q[LUGRE] > 0.0:
        r = v / q[VS]
        g = q[FC] + (q[FS] - q[FC]) * math.exp(-r * r)
        z = y[8]
        dz = v - q[SIG0] * abs(v) * z / g
        dy[8] = dz
        f_fric += q[SIG0] * z + q[SIG1] * dz
    else:
        dy[8] = 0.0
    drive = pa * q[AA] - pb * q[AB] - f_load
    if (x <= 0.0 and v <= 0.0 and drive - f_fric <= 0.0) or (
        x >= q[STROKE] and v >= 0.0 and drive - f_fric >= 0.0
    ):
        dy[3] = dy[4] = 0.0
        v = 0.0
        dy[8] = 0.0
    else:
        dy[3] = v
        dy[4] = (drive - f_fric) / q[MASS]
    va = q[V0A] + q[AA] * x
    vb = q[V0B] + q[AB] * (q[STROKE] - x)
    dy[1] = (q_pa - q_at - q_x - q[AA] * v) / _cap(pa, va, q[V0A], q)
    dy[2] = (q_pb - q_bt + q_x + q[AB] * v) / _cap(pb, vb, q[V0B], q)
    return qp


@njit(cache=True)
def integrate(y0, inputs, t0, dt_in, n_sub, q, every):
    """RK4; inputs (n x 4: spool, disp, rev/s, viscosity ratio) held linear in a sample."""
    n = inputs.shape[0]
    n_rec = ((n - 1) * n_sub) // every + 1
    rec = np.empty((n_rec, 5))  # pp, pa, pb, qp, x
    y = y0.copy()
    k1, k2, k3, k4, yt = np.zeros(NS), np.zeros(NS), np.zeros(NS), np.zeros(NS), np.zeros(NS)
    u = np.empty(4)
    h = dt_in / n_sub
    scratch = np.zeros(NS)
    qp = _rhs(y, inputs[0], t0, q, scratch)
    rec[0, 0], rec[0, 1], rec[0, 2], rec[0, 3], rec[0, 4] = y[0], y[1], y[2], qp, y[3]
    r, step = 1, 0
    for k in range(n - 1):
        for j in range(n_sub):
            t = t0 + k * dt_in + j * h
            for stage in range(4):
                f = (j + (0.0, 0.5, 0.5, 1.0)[stage]) / n_sub
                for i in range(4):
                    u[i] = inputs[k, i] + f * (inputs[k + 1, i] - inputs[k, i])
                if stage == 0:
                    _rhs(y, u, t, q, k1)
                elif stage == 1:
                    for i in range(NS):
                        yt[i] = y[i] + 0.5 * h * k1[i]
                    _rhs(yt, u, t + 0.5 * h, q, k2)
                elif stage == 2:
                    for i in range(NS):
                        yt[i] = y[i] + 0.5 * h * k2[i]
                    _rhs(yt, u, t + 0.5 * h, q, k3)
                else:
                    for i in range(NS):
                        yt[i] = y[i] + h * k3[i]
                    qp = _rhs(yt, u, t + h, q, k4)
            for i in range(NS):
                y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            for i in range(3):
                y[i] = max(y[i], 0.0)
            if y[3] < 0.0:
                y[3], y[4] = 0.0, max(y[4], 0.0)
            elif y[3] > q[STROKE]:
                y[3], y[4] = q[STROKE], min(y[4], 0.0)
            step += 1
            if step % every == 0:
                qp = _rhs(y, u, t + h, q, scratch)
                rec[r, 0], rec[r, 1], rec[r, 2], rec[r, 3], rec[r, 4] = y[0], y[1], y[2], qp, y[3]
                r += 1
    return rec


def viscosity_ratio(temp_c: np.ndarray, activation_k: float = 2800.0) -> np.ndarray:
    """nu(T) / nu(40 degC) from an Arrhenius law exp(E (1/T - 1/T40))."""
    tk = np.asarray(temp_c) + 273.15
    return np.exp(activation_k * (1.0 / tk - 1.0 / 313.15))


def run(
    t: np.ndarray,
    spool_pct: np.ndarray,
    disp_pct: np.ndarray,
    rpm: np.ndarray,
    oil_c: np.ndarray,
    q: np.ndarray,
    rod0_m: float = 0.1,
) -> np.ndarray:
    """Plant record at 1 kHz: columns PP, PA, PB (Pa), QP (m^3/s), x (m)."""
    inputs = np.column_stack(
        [
            np.clip(spool_pct, -100, 100) / 100,
            np.clip(disp_pct, 0, 100) / 100,
            rpm / 60.0,
            viscosity_ratio(oil_c),
        ]
    )
    dt = float(t[1] - t[0])
    n_sub = int(round(dt / 2e-4))
    y0 = np.zeros(NS)
    y0[0] = 200e5
    y0[2] = 2e5
    y0[1] = (q[FG] + q[K1] * (rod0_m - q[XREF]) + y0[2] * q[AB]) / q[AA]
    y0[3] = rod0_m
    return integrate(y0, inputs, float(t[0]), dt, n_sub, q, n_sub // 10)


def sensors(
    rec_1khz: np.ndarray,
    rng: np.random.Generator,
    delay_s: float = 0.0,
    filter_hz: float = 0.0,
    filter_zeta: float = 0.7,
) -> dict[str, np.ndarray]:
    """100 Hz readings: optional 2nd-order filter and delay, noise, range, 0.01 resolution."""
    fs = 1000.0
    out = {}
    for j, (name, unit, noise, hi) in enumerate(
        (
            ("PP", 1e5, 0.3, 400.0),
            ("PA", 1e5, 0.3, 400.0),
            ("PB", 1e5, 0.3, 400.0),
            ("QP", 1e-3 / 60, 0.1, 60.0),
        )
    ):
        x = rec_1khz[:, j] / unit
        if filter_hz > 0.0:
            w = 2 * math.pi * filter_hz
            b, a = bilinear([w * w], [1.0, 2 * filter_zeta * w, w * w], fs)
            x, _ = lfilter(b, a, x, zi=x[0] * _steady_zi(b, a))
        if delay_s > 0.0:
            shift = int(round(delay_s * fs))
            x = np.concatenate([np.full(shift, x[0]), x[:-shift]]) if shift else x
        x = x[::10] + rng.normal(0.0, noise, size=x[::10].shape)
        out[name] = np.round(np.clip(x, 0.0, hi), 2)
    rod = rec_1khz[::10, 4] * 1e3 + rng.normal(0.0, 0.5, size=rec_1khz[::10].shape[0])
    out["RodPos"] = np.round(np.clip(rod, 0.0, 500.0), 2)
    return out


def _steady_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    from scipy.signal import lfilter_zi

    return lfilter_zi(b, a)
