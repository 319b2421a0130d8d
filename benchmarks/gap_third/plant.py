"""The third plant's boom loop: its own valve, pump, boom and oil formulations (SI inside).

Written apart from `monitor/` (see README.md here).  One parameter vector `prm` (indices
below, names in `NAMES`), one numba RK4 kernel at a fixed step; the recorded states come
out at 1 kHz for the transducer models in `sensors.py`.

Formulations (textbook forms, Merritt; Jelali & Kroll; Manring):
- valve: closed-centre 4/3, metering area with notches (area = (1-n) u + n u^2 of the
  opening u past the overlap), an orifice law whose laminar-turbulent transition pressure
  follows a Reynolds number (grows with viscosity^2 and at small openings), laminar land
  clearances, a spool as a position-controlled second-order system with a velocity limit
  and a steady flow force that closes it;
- pump: swashplate moved by a control piston (first-order with a slew limit) towards the
  lower of the displacement command and a pressure compensator; Wilson slip leakage
  (proportional to pressure over viscosity, or not when worn); engine speed droops with
  the pump torque (mechanical efficiency) behind a governor lag, with a speed ripple;
- load: a boom on a pivot lifted by the cylinder (lever and boom angle from the pose),
  inertia J / h(x)^2 that changes with the pose, gravity moment / h(x) with the boom's
  angle, a stick whose moment may swing with the pose, end stops as stiff springs;
- oil: Vogel viscosity from OilTemp, a bulk modulus that rises with pressure (tangent
  modulus) and falls with temperature, isothermal entrained air, hoses whose capacitance
  falls with pressure; a return line with a quadratic back pressure;
- friction: pressure-dependent viscous seal friction, optionally LuGre (bristle state).
"""

from __future__ import annotations

import numba
import numpy as np

NAMES = (
    "rho",
    "beta0",
    "beta_slope",
    "nu40",
    "d_max",
    "tau_cp",
    "rate_cp",
    "p_comp_start",
    "p_comp_full",
    "p_relief_crack",
    "p_relief_full",
    "v_line",
    "kv_pa",
    "kv_at",
    "kv_pb",
    "kv_bt",
    "notch",
    "overlap",
    "dpt0",
    "k_clear",
    "wn_spool",
    "zeta_spool",
    "rate_spool",
    "flow_force",
    "area_a",
    "area_b",
    "stroke",
    "v0a",
    "v0b",
    "c_visc",
    "visc_p_share",
    "arm_a",
    "arm_r",
    "len0",
    "phi_mid",
    "tilt",
    "inertia",
    "grav_moment",
    "stick_moment",
    "stick_angle",
    "fc",
    "fs",
    "vs",
    "sigma0",
    "sigma1",
    "pump_slip40",
    "slip_visc_exp",
    "c_int",
    "c_check",
    "air",
    "hose_cap",
    "hose_p",
    "tau_engine",
    "droop",
    "eta_m",
    "pt0",
    "kt",
    "f_per",
    "w_per",
    "k_stop",
    "c_stop",
    "visc_fric_exp",
    "q_max",
)
IX = {name: i for i, name in enumerate(NAMES)}
(
    RHO,
    BETA0,
    BETA_SLOPE,
    NU40,
    D_MAX,
    TAU_CP,
    RATE_CP,
    P_CS,
    P_CF,
    P_RC,
    P_RF,
    V_LINE,
    KV_PA,
    KV_AT,
    KV_PB,
    KV_BT,
    NOTCH,
    OVERLAP,
    DPT0,
    K_CLEAR,
    WN_S,
    ZETA_S,
    RATE_S,
    FLOW_FORCE,
    AREA_A,
    AREA_B,
    STROKE,
    V0A,
    V0B,
    C_VISC,
    VISC_P,
    ARM_A,
    ARM_R,
    LEN0,
    PHI_MID,
    TILT,
    INERTIA,
    GRAV_M,
    STICK_M,
    STICK_ANG,
    FC,
    FS,
    VS,
    SIGMA0,
    SIGMA1,
    SLIP40,
    SLIP_EXP,
    C_INT,
    C_CHECK,
    AIR,
    HOSE_CAP,
    HOSE_P,
    TAU_E,
    DROOP,
    ETA_M,
    PT0,
    KT,
    F_PER,
    W_PER,
    K_STOP,
    C_STOP,
    VF_EXP,
    Q_MAX,
) = range(len(NAMES))
# states: pump line, chambers A and B, tank line (Pa); rod (m, m/s); spool (-1..1, 1/s);
# swashplate (0..1); LuGre bristle (m); engine speed (rpm)
N_STATES = 11
BAR = 1e5
P_ATM = 1.013e5
VOGEL_B, VOGEL_C = 839.0, 95.0  # degC; 46 cSt at 40 degC, 6.8 cSt at 100 degC


@numba.njit(cache=True)
def viscosity_ratio(temp_c: float) -> float:
    """nu(T) / nu(40 degC), Vogel equation."""
    return np.exp(VOGEL_B / (temp_c + VOGEL_C) - VOGEL_B / (40.0 + VOGEL_C))


@numba.njit(cache=True)
def boom_geometry(prm: np.ndarray, x: float) -> tuple[float, float]:
    """Lever arm h (m) of the cylinder about the boom pivot and the boom angle (rad)."""
    a, r = prm[ARM_A], prm[ARM_R]
    length = prm[LEN0] + x
    c = (a * a + r * r - length * length) / (2.0 * a * r)
    c = min(0.999, max(-0.999, c))
    phi = np.arccos(c)
    return a * r * np.sin(phi) / length, phi - prm[PHI_MID] + prm[TILT]


@numba.njit(cache=True)
def load_force(prm: np.ndarray, x: float) -> float:
    """Gravity force (N) against extension at rod position x (boom and stick moments)."""
    h, theta = boom_geometry(prm, x)
    stick = prm[STICK_M] * (np.cos(theta + prm[STICK_ANG]) - np.cos(prm[TILT] + prm[STICK_ANG]))
    return (prm[GRAV_M] * np.cos(theta) + stick) / h


@numba.njit(cache=True)
def _opening(xs: float, overlap: float) -> float:
    d = abs(xs) - overlap
    e = 2e-3
    u = 0.5 * (d + np.sqrt(d * d + e * e)) - 0.5 * e
    return max(0.0, u / (1.0 - overlap))


@numba.njit(cache=True)
def _edge(kv: float, area: float, dp: float, dpt: float) -> float:
    """Orifice flow (m^3/s): turbulent sqrt(dp) far above dpt, laminar below."""
    return kv * area * dp / np.sqrt(abs(dp) + dpt)


@numba.njit(cache=True)
def _beta(prm: np.ndarray, p: float, temp_c: float) -> float:
    """Effective bulk modulus (Pa): oil's tangent modulus, isothermal air, gauge p."""
    beta_oil = (prm[BETA0] + prm[BETA_SLOPE] * (p - 100 * BAR)) * (1.0 - 0.004 * (temp_c - 40.0))
    a0 = prm[AIR]
    if a0 <= 0.0:
        return beta_oil
    p_abs = max(p + P_ATM, 0.2 * P_ATM)
    va = a0 * P_ATM / p_abs
    frac = va / (1.0 - a0 + va)
    return 1.0 / ((1.0 - frac) / beta_oil + frac / p_abs)


@numba.njit(cache=True)
def _capacity(prm: np.ndarray, volume: float, p: float, temp_c: float) -> float:
    """dV/dp (m^3/Pa) of a volume of oil and its hose (hoses stiffen with pressure)."""
    hose = prm[HOSE_CAP] / (1.0 + max(p, 0.0) / prm[HOSE_P])
    return volume / _beta(prm, p, temp_c) + hose


@numba.njit(cache=True)
def _valve(prm, s, cmd, nu_r, ds):
    """Edge flows P->A, A->T, P->B, B->T (m^3/s); sets the spool's derivatives."""
    p_p, p_a, p_b, p_t, xs, vs = s[0], s[1], s[2], s[3], s[6], s[7]
    u = _opening(xs, prm[OVERLAP])
    area = (1.0 - prm[NOTCH]) * u + prm[NOTCH] * u * u
    dpt_u = prm[DPT0] * nu_r * nu_r * (1.0 + 0.1 / (u + 0.01))
    kcl = prm[K_CLEAR] / nu_r
    if xs >= 0.0:
        q_pa = _edge(prm[KV_PA], area, p_p - p_a, dpt_u) + kcl * (p_p - p_a)
        q_bt = _edge(prm[KV_BT], area, p_b - p_t, dpt_u) + kcl * (p_b - p_t)
        q_pb = kcl * (p_p - p_b)
        q_at = kcl * (p_a - p_t)
        drop = abs(p_p - p_a) + abs(p_b - p_t)
        sgn = 1.0
    else:
        q_pb = _edge(prm[KV_PB], area, p_p - p_b, dpt_u) + kcl * (p_p - p_b)
        q_at = _edge(prm[KV_AT], area, p_a - p_t, dpt_u) + kcl * (p_a - p_t)
        q_pa = kcl * (p_p - p_a)
        q_bt = kcl * (p_b - p_t)
        drop = abs(p_p - p_b) + abs(p_a - p_t)
        sgn = -1.0
    # the steady flow force closes the spool against its position control
    x_ref = cmd - sgn * prm[FLOW_FORCE] * area * drop / 1e7
    wn = prm[WN_S]
    ds[6] = vs
    ds[7] = wn * wn * (x_ref - xs) - 2.0 * prm[ZETA_S] * wn * vs
    return q_pa, q_at, q_pb, q_bt


@numba.njit(cache=True)
def _pump(prm, s, disp_cmd, n_set, nu_r, ds):
    """Pump outlet flow and relief flow (m^3/s); sets swashplate and engine derivatives."""
    p_p, alpha, n = s[0], s[8], s[10]
    comp = min(1.0, max(0.0, (prm[P_CF] - p_p) / (prm[P_CF] - prm[P_CS])))
    target = min(disp_cmd, comp)
    ds[8] = min(prm[RATE_CP], max(-prm[RATE_CP], (target - alpha) / prm[TAU_CP]))
    q_th = max(alpha, 0.0) * prm[D_MAX] * n / 60.0
    slip = prm[SLIP40] * max(p_p, 0.0) / nu_r ** prm[SLIP_EXP]
    q_rel = prm[Q_MAX] * max(0.0, p_p - prm[P_RC]) / (prm[P_RF] - prm[P_RC])
    torque = max(alpha, 0.0) * prm[D_MAX] * max(p_p, 0.0) / (2.0 * np.pi * prm[ETA_M])
    ds[10] = (n_set - prm[DROOP] * torque - n) / prm[TAU_E]
    return q_th - slip, q_rel


@numba.njit(cache=True)
def _rod(prm, s, nu_r, t, ds):
    """Rod velocity and acceleration (boom dynamics), LuGre bristle derivative."""
    p_a, p_b, x, v, z = s[1], s[2], s[4], s[5], s[9]
    visc = prm[C_VISC] * (1.0 - prm[VISC_P] + prm[VISC_P] * (p_a + p_b) / (200 * BAR))
    f_fric = visc * v * nu_r ** prm[VF_EXP]
    ds[9] = 0.0
    if prm[FC] > 0.0:  # LuGre
        g = prm[FC] + (prm[FS] - prm[FC]) * np.exp(-((v / prm[VS]) ** 2))
        dz = v - prm[SIGMA0] * abs(v) * z / g
        ds[9] = dz
        f_fric += prm[SIGMA0] * z + prm[SIGMA1] * np.exp(-((v / prm[VS]) ** 2)) * dz
    f_stop = 0.0
    if x < 0.0:
        f_stop = -prm[K_STOP] * x - prm[C_STOP] * min(v, 0.0)
    elif x > prm[STROKE]:
        f_stop = -prm[K_STOP] * (x - prm[STROKE]) - prm[C_STOP] * max(v, 0.0)
    h, _ = boom_geometry(prm, x)
    h2, _ = boom_geometry(prm, x + 1e-4)
    m_eq = prm[INERTIA] / (h * h)
    dm = (prm[INERTIA] / (h2 * h2) - m_eq) / 1e-4  # Lagrange: the pose-dependent inertia
    f_per = prm[F_PER] * np.sin(prm[W_PER] * t)
    force = p_a * prm[AREA_A] - p_b * prm[AREA_B] - load_force(prm, x) - f_fric + f_stop + f_per
    ds[4] = v
    ds[5] = (force - 0.5 * dm * v * v) / m_eq


@numba.njit(cache=True)
def derivatives(prm, s, cmd, disp_cmd, n_set, temp_c, t, ds):
    """All state derivatives into ds; returns the pump outlet flow (m^3/s)."""
    p_p, p_a, p_b, p_t, x, v = s[0], s[1], s[2], s[3], s[4], s[5]
    nu_r = viscosity_ratio(temp_c)
    q_pa, q_at, q_pb, q_bt = _valve(prm, s, cmd, nu_r, ds)
    q_pump, q_rel = _pump(prm, s, disp_cmd, n_set, nu_r, ds)
    v_a = prm[V0A] + prm[AREA_A] * x
    v_b = prm[V0B] + prm[AREA_B] * (prm[STROKE] - x)
    q_int = prm[C_INT] * (p_a - p_b)
    q_chk = prm[C_CHECK] * max(p_a - p_t, 0.0)
    ds[0] = (q_pump - q_pa - q_pb - q_rel) / _capacity(prm, prm[V_LINE], p_p, temp_c)
    ds[1] = (q_pa - q_at - prm[AREA_A] * v - q_int - q_chk) / _capacity(prm, v_a, p_a, temp_c)
    ds[2] = (q_pb - q_bt + prm[AREA_B] * v + q_int) / _capacity(prm, v_b, p_b, temp_c)
    q_t = max(q_at + q_bt + q_rel + q_chk, 0.0)
    ds[3] = (prm[PT0] + prm[KT] * q_t * q_t - p_t) / 0.005
    _rod(prm, s, nu_r, t, ds)
    return q_pump


@numba.njit(cache=True)
def _clamp(prm, s):
    for i in range(4):
        s[i] = max(s[i], 0.0)  # make-up checks: no chamber below tank
    if abs(s[7]) > prm[RATE_S]:
        s[7] = np.sign(s[7]) * prm[RATE_S]
    s[8] = min(1.0, max(0.0, s[8]))


@numba.njit(cache=True)
def run(prm, state0, spool, disp, n_set, temp, n_ripple, dt):
    """Integrate; inputs at 100 Hz (held), output rows at 1 kHz.

    Columns: PP, PA, PB (Pa), QP (m^3/s), x (m), v (m/s), spool, swashplate, n (rpm)."""
    rows = spool.shape[0]
    per_ms = int(round(1e-3 / dt))
    out = np.empty((rows * 10, 9))
    s = state0.copy()
    k1 = np.empty(N_STATES)
    k2 = np.empty(N_STATES)
    k3 = np.empty(N_STATES)
    k4 = np.empty(N_STATES)
    tmp = np.empty(N_STATES)
    t = 0.0
    for i in range(rows):
        ns = n_set[i] + n_ripple[i]
        for j in range(10):
            q = 0.0
            for _ in range(per_ms):
                q = derivatives(prm, s, spool[i], disp[i], ns, temp[i], t, k1)
                for m in range(N_STATES):
                    tmp[m] = s[m] + 0.5 * dt * k1[m]
                derivatives(prm, tmp, spool[i], disp[i], ns, temp[i], t + 0.5 * dt, k2)
                for m in range(N_STATES):
                    tmp[m] = s[m] + 0.5 * dt * k2[m]
                derivatives(prm, tmp, spool[i], disp[i], ns, temp[i], t + 0.5 * dt, k3)
                for m in range(N_STATES):
                    tmp[m] = s[m] + dt * k3[m]
                derivatives(prm, tmp, spool[i], disp[i], ns, temp[i], t + dt, k4)
                for m in range(N_STATES):
                    s[m] += dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
                _clamp(prm, s)
                t += dt
            r = i * 10 + j
            out[r, 0], out[r, 1], out[r, 2], out[r, 3] = s[0], s[1], s[2], q
            out[r, 4], out[r, 5], out[r, 6], out[r, 7], out[r, 8] = s[4], s[5], s[6], s[8], s[10]
    return out
