"""The fourth plant's right-hand side and its fixed-step RK4 integration (numba)."""

from __future__ import annotations

import numba
import numpy as np

from benchmarks.gap_fourth import plant as pl
from benchmarks.gap_fourth.plant import (
    A_CAP,
    A_ROD,
    AC_CRACK,
    AC_K,
    AIR_EPS,
    B_NOTCH_BLOCK,
    C_STOP,
    C_STRUCT,
    C_TH,
    C_VISC,
    D_MAX,
    DP_REG,
    ETA_HM,
    F_PER_AMP,
    F_PER_HZ,
    F_PER_PHASE,
    FILTER_R40,
    GOV_TAU,
    HA0,
    HA_COOL,
    HOSE_CF,
    HOSE_CS,
    HOSE_PUMP_SHARE,
    HOSE_TAU,
    J_ENG,
    K_FULL_AT,
    K_FULL_BT,
    K_FULL_PA,
    K_FULL_PB,
    K_LINE,
    K_STOP,
    K_STRUCT,
    LAP,
    LEAK_AB_K,
    LEAK_AT_K,
    M1,
    M2,
    MU_REF,
    P_ATM,
    PC_FULL,
    PC_LEAD,
    PC_START,
    PC_WN,
    PC_ZETA,
    RELIEF_CRACK,
    RELIEF_FULL,
    RELIEF_Q,
    RETURN_KT,
    RETURN_TAU,
    RHO,
    RIPPLE,
    SLIP40,
    SP_SLOW_TAU,
    SP_SLOW_VMAX,
    SP_TSOL,
    SP_WN,
    SP_ZETA,
    STROKE,
    STROKE_S,
    SV_RATE,
    SV_TAU,
    T_AMB,
    T_PARASITIC,
    T_RATED,
    T_THERMO,
    V_DEAD_A,
    V_DEAD_B,
    V_PUMP,
    VISC_SHARE,
    W_FULLLOAD,
    W_NOLOAD,
    WORN_K,
)

# columns of the 1 ms trace the kernel writes
OUT_NAMES = ("PP", "PA", "PB", "QP", "x1", "v1", "we", "T", "xs", "pA", "pB", "pT", "x2")
N_OUT = len(OUT_NAMES)


@numba.njit(cache=True)
def _root(dp, reg):
    return dp / (dp * dp + reg * reg) ** 0.25


@numba.njit(cache=True)
def _spool(p, x, cmd, dx):
    dx[2] = (cmd - x[2]) / p[SP_TSOL]
    if p[SP_SLOW_TAU] > 0.0:
        rate = (x[2] - x[0]) / p[SP_SLOW_TAU]
        vmax = p[SP_SLOW_VMAX]
        dx[0] = min(max(rate, -vmax), vmax)
        dx[1] = -x[1] / 1e-3
    else:
        wn = p[SP_WN]
        dx[0] = x[1]
        dx[1] = wn * wn * (x[2] - x[0]) - 2.0 * p[SP_ZETA] * wn * x[1]


@numba.njit(cache=True)
def _pump(p, x, disp, dx):
    # the spool's spring chamber fed through an orifice: a dynamic (lead) pressure feedback
    c_t = (x[6] + p[PC_LEAD] * dx[6] - p[PC_START]) / (p[PC_FULL] - p[PC_START])
    c_t = min(max(c_t, 0.0), 1.2)
    wn = p[PC_WN]
    dx[4] = x[5]
    dx[5] = wn * wn * (c_t - x[4]) - 2.0 * p[PC_ZETA] * wn * x[5]
    alpha_t = disp * (1.0 - min(max(x[4], 0.0), 1.0))
    rate = (alpha_t - x[3]) / p[SV_TAU]
    rate = min(max(rate, -p[SV_RATE]), p[SV_RATE])
    if (x[3] <= 0.0 and rate < 0.0) or (x[3] >= 1.0 and rate > 0.0):
        rate = 0.0
    dx[3] = rate


@numba.njit(cache=True)
def _engine(p, x, tq_noise, t_pump, dx):
    target = p[T_RATED] * (p[W_NOLOAD] - x[13]) / (p[W_NOLOAD] - p[W_FULLLOAD])
    target = min(max(target, 0.0), 1.15 * p[T_RATED])
    dx[14] = (target - x[14]) / p[GOV_TAU]
    ripple = p[RIPPLE] * x[14] * np.sin(1.5 * x[15])
    dx[13] = (x[14] + ripple + tq_noise - t_pump) / p[J_ENG]
    dx[15] = x[13]


@numba.njit(cache=True)
def _mechanics(p, x, t, mu_ratio, dx):
    x1, v1, x2, v2 = x[9], x[10], x[11], x[12]
    f_h = x[7] * p[A_CAP] - x[8] * p[A_ROD]
    visc = p[C_VISC] * (1.0 - p[VISC_SHARE] + p[VISC_SHARE] * mu_ratio)
    f_fr = visc * v1 + pl.seal_friction(p, v1, x[7], x[8])
    f_s = p[K_STRUCT] * (x1 - x2) + p[C_STRUCT] * (v1 - v2)
    f_stop = 0.0
    if x1 < 0.0:
        f_stop = max(-p[K_STOP] * x1 - p[C_STOP] * v1, 0.0)
    elif x1 > p[STROKE]:
        f_stop = min(-p[K_STOP] * (x1 - p[STROKE]) - p[C_STOP] * v1, 0.0)
    f_ext = p[F_PER_AMP] * np.sin(2.0 * np.pi * p[F_PER_HZ] * t + p[F_PER_PHASE])
    dx[9] = v1
    dx[10] = (f_h - f_fr - f_s + f_stop) / p[M1]
    dx[11] = v2
    dx[12] = (f_s - pl.gravity_force(p, x2) + f_ext) / p[M2]


@numba.njit(cache=True)
def derivs(p, x, t, cmd, disp, tq_noise, dx, out):
    """dx/dt of the loop; out: port pressures PA, PB (Pa), pump outlet flow (m^3/s)."""
    nu = pl.viscosity_cst(p, x[16]) * 1e-6
    mu = nu * p[RHO]
    mu_ratio = mu / p[MU_REF]
    pp, pa, pb, pt = x[6], x[7], x[8], x[23]
    x1 = x[9]
    _spool(p, x, cmd, dx)
    y = min(max(x[0], -1.0), 1.0) * p[STROKE_S]
    k_a = p[K_LINE] if x[0] > 0.0 else pl.cushion_k(p, x1)
    k_b = p[K_LINE] if x[0] < 0.0 else pl.cushion_k(p, p[STROKE] - x1)
    a_pa = p[K_FULL_PA] * (1.0 - p[B_NOTCH_BLOCK])
    q_pa = pl.edge_flow(p, pp - pa, y - p[LAP], a_pa, nu, k_a)
    q_at = pl.edge_flow(p, pa - pt, -y - p[LAP], p[K_FULL_AT], nu, k_a)
    q_pb = pl.edge_flow(p, pp - pb, -y - p[LAP], p[K_FULL_PB], nu, k_b)
    q_bt = pl.edge_flow(p, pb - pt, y - p[LAP], p[K_FULL_BT], nu, k_b)
    qa_in = q_pa - q_at
    qb_in = q_pb - q_bt
    reg = p[DP_REG]
    ac_a = p[AC_K] * _root(max(pt - pa - p[AC_CRACK], 0.0), reg)
    ac_b = p[AC_K] * _root(max(pt - pb - p[AC_CRACK], 0.0), reg)
    q_ab = p[LEAK_AB_K] * _root(pa - pb, reg)
    q_alt = p[LEAK_AT_K] * _root(max(pa - pt, 0.0), reg)
    slip = p[SLIP40] * pp / mu_ratio
    worn = p[WORN_K] * _root(max(pp, 0.0), reg)
    q_pump = x[3] * p[D_MAX] * x[13] - slip - worn
    q_rel = 0.0
    if pp > p[RELIEF_CRACK]:
        q_rel = p[RELIEF_Q] * (pp - p[RELIEF_CRACK]) / (p[RELIEF_FULL] - p[RELIEF_CRACK])
    # air and hoses: the free air share relaxes (Henry), the hoses creep
    v_a = p[V_DEAD_A] + p[A_CAP] * max(x1, 0.0)
    v_b = p[V_DEAD_B] + p[A_ROD] * max(p[STROKE] - x1, 0.0)
    dx[17] = pl.air_rate(p, pa, x[17])
    dx[18] = pl.air_rate(p, pb, x[18])
    dx[19] = pl.air_rate(p, pp, x[19])
    sh = p[HOSE_PUMP_SHARE]
    dx[20] = (p[HOSE_CS] * max(pa, 0.0) - x[20]) / p[HOSE_TAU]
    dx[21] = (p[HOSE_CS] * max(pb, 0.0) - x[21]) / p[HOSE_TAU]
    dx[22] = (p[HOSE_CS] * sh * max(pp, 0.0) - x[22]) / p[HOSE_TAU]
    eps = p[AIR_EPS]
    gas_a = v_a * eps * P_ATM / max(pa + P_ATM, 2e4) * dx[17]
    gas_b = v_b * eps * P_ATM / max(pb + P_ATM, 2e4) * dx[18]
    gas_p = p[V_PUMP] * eps * P_ATM / max(pp + P_ATM, 2e4) * dx[19]
    c_a = pl.chamber_capacity(p, pa, v_a, x[17]) + p[HOSE_CF]
    c_b = pl.chamber_capacity(p, pb, v_b, x[18]) + p[HOSE_CF]
    c_p = pl.chamber_capacity(p, pp, p[V_PUMP], x[19]) + p[HOSE_CF] * sh
    v1 = x[10]
    dx[6] = (q_pump - q_pa - q_pb - q_rel - dx[22] + gas_p) / c_p
    dx[7] = (qa_in + ac_a - q_ab - q_alt - p[A_CAP] * v1 - dx[20] + gas_a) / c_a
    dx[8] = (qb_in + ac_b + q_ab + p[A_ROD] * v1 - dx[21] + gas_b) / c_b
    q_ret = q_at + q_bt + q_rel + q_alt - ac_a - ac_b
    filt = min(p[FILTER_R40] * mu_ratio * q_ret, 2.5e5)
    pt_target = max(filt + p[RETURN_KT] * q_ret * abs(q_ret), 0.0)
    dx[23] = (pt_target - pt) / p[RETURN_TAU]
    _pump(p, x, disp, dx)
    _mechanics(p, x, t, mu_ratio, dx)
    t_pump = x[3] * p[D_MAX] * max(pp, 0.0) / p[ETA_HM] + p[T_PARASITIC]
    _engine(p, x, tq_noise, t_pump, dx)
    cool = p[HA0] + p[HA_COOL] * min(max((x[16] - p[T_THERMO]) / 5.0, 0.0), 1.0)
    dx[16] = (t_pump * x[13] - cool * (x[16] - p[T_AMB])) / p[C_TH]
    out[0] = pa + qa_in * abs(qa_in) / (k_a * k_a)
    out[1] = pb + qb_in * abs(qb_in) / (k_b * k_b)
    out[2] = q_pump


@numba.njit(cache=True)
def _clamp(x):
    for i in (6, 7, 8):
        if x[i] < -0.9e5:
            x[i] = -0.9e5
    x[3] = min(max(x[3], 0.0), 1.0)
    for i in (17, 18, 19):
        x[i] = min(max(x[i], 0.0), 1.0)


@numba.njit(cache=True)
def integrate(p, x0, cmd_ms, disp_ms, noise_ms, dt, steps_per_ms):
    """RK4 at `dt` with inputs held over each millisecond; returns the 1 ms trace
    (columns OUT_NAMES, SI) and the final state."""
    n = cmd_ms.shape[0]
    x = x0.copy()
    k1 = np.empty_like(x)
    k2 = np.empty_like(x)
    k3 = np.empty_like(x)
    k4 = np.empty_like(x)
    xt = np.empty_like(x)
    o = np.zeros(3)
    trace = np.empty((n, N_OUT))
    t = 0.0
    for i in range(n):
        c, d, w = cmd_ms[i], disp_ms[i], noise_ms[i]
        derivs(p, x, t, c, d, w, k1, o)
        trace[i, 0] = x[6]
        trace[i, 1] = o[0]
        trace[i, 2] = o[1]
        trace[i, 3] = o[2]
        trace[i, 4] = x[9]
        trace[i, 5] = x[10]
        trace[i, 6] = x[13]
        trace[i, 7] = x[16]
        trace[i, 8] = x[0]
        trace[i, 9] = x[7]
        trace[i, 10] = x[8]
        trace[i, 11] = x[23]
        trace[i, 12] = x[11]
        for s in range(steps_per_ms):
            if s > 0:
                derivs(p, x, t, c, d, w, k1, o)
            for j in range(x.size):
                xt[j] = x[j] + 0.5 * dt * k1[j]
            derivs(p, xt, t + 0.5 * dt, c, d, w, k2, o)
            for j in range(x.size):
                xt[j] = x[j] + 0.5 * dt * k2[j]
            derivs(p, xt, t + 0.5 * dt, c, d, w, k3, o)
            for j in range(x.size):
                xt[j] = x[j] + dt * k3[j]
            derivs(p, xt, t + dt, c, d, w, k4, o)
            for j in range(x.size):
                x[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
            _clamp(x)
            t += dt
    return trace, x
