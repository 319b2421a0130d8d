"""The boom loop: pump, closed-centre valve, cylinder and load, integrated with fixed-step RK4.

State (SI): rod position x [m], rod velocity v [m/s], cap pressure pA, rod-side pressure pB,
pump line pressure pP [Pa gauge], swash (displacement share) eps, spool position u and its
rate du (share of full stroke), and the flow transducer's lagged reading qs [m^3/s].

Per 10 ms sample the inputs are the spool command (share, -1..1), the displacement command
(share, 0..1), engine speed [rpm], oil temperature [degC] and the fault severity; the fault
kind and the payload factor are fixed per run.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .params import IDX, viscosity_cst

SAMPLE_S = 0.01
SUBSTEPS = 20
P_ATM = 1.0e5
P_VAPOUR = -0.9e5  # gauge: the oil cavitates below it
FLOW_SENSOR_TAU_S = 0.015  # gear flowmeter and its electronics

NONE, PISTON_WEAR, SPOOL_WEAR, SPOOL_STROKE = 0, 1, 2, 3
FAULTS = {
    "normal": NONE,
    "piston_wear": PISTON_WEAR,
    "spool_wear": SPOOL_WEAR,
    "spool_stroke": SPOOL_STROKE,
}
PISTON_LEAK_MAX = 6e-12  # m^3/(s Pa) across the piston at severity 1 and 40 degC
SPOOL_WEAR_AREA = 0.08  # share of a full opening each worn edge leaks at centre, severity 1
SPOOL_WEAR_REACH = 0.25  # the worn band: the leak fades to nothing at 25 % stroke
SPOOL_STROKE_LOSS = 0.5  # the spool reaches 1 - 0.5 s of its stroke

N_STATE = 9
X, V, PA, PB, PP, EPS, U, DU, QS = range(N_STATE)

_i = IDX  # short alias for the kernel's constant indices
(
    I_DISP,
    I_TAU,
    I_CCR,
    I_CFU,
    I_PLEAK,
    I_RIP,
    I_RCR,
    I_RFU,
    I_VLINE,
    I_BLINE,
    I_BOIL,
    I_AIR,
    I_RHO,
    I_NU40,
    I_NU100,
    I_KV,
    I_DPL,
    I_OVP,
    I_OVT,
    I_AEXP,
    I_VLEAK,
    I_WN,
    I_ZETA,
    I_PT,
    I_BORE,
    I_ROD,
    I_STROKE,
    I_V0,
    I_MASS,
    I_GRAV,
    I_VISC,
    I_COUL,
    I_STRB,
    I_VSTR,
    I_SEAL,
    I_STOPK,
    I_STOPC,
) = (
    _i[n]
    for n in (
        "pump_disp_m3",
        "pump_tau_s",
        "comp_crack_pa",
        "comp_full_pa",
        "pump_leak_m3_spa",
        "pump_ripple",
        "relief_crack_pa",
        "relief_full_pa",
        "line_volume_m3",
        "line_beta_pa",
        "oil_beta_pa",
        "air_fraction",
        "rho_kg_m3",
        "nu40_cst",
        "nu100_cst",
        "kv_full",
        "dp_lam_pa",
        "overlap_p",
        "overlap_t",
        "area_exp",
        "valve_leak_m3_spa",
        "spool_wn_rad_s",
        "spool_zeta",
        "tank_pa",
        "bore_m",
        "rod_m",
        "stroke_m",
        "dead_volume_m3",
        "mass_kg",
        "gravity_n",
        "visc_friction_ns_m",
        "coulomb_n",
        "stribeck_ratio",
        "stribeck_v_m_s",
        "seal_drag",
        "stop_k_n_m",
        "stop_c_ns_m",
    )
)


@njit(cache=True)
def opening(z, overlap, exponent):
    """Metering opening (share of full) of an edge at spool travel z toward opening it."""
    if z <= overlap:
        return 0.0
    s = (z - overlap) / (1.0 - overlap)
    return min(s, 1.0) ** exponent


@njit(cache=True)
def orifice(kv, area, dp, dp_lam):
    """Flow through an opening: sqrt(dp) when turbulent, linear in dp below dp_lam."""
    return kv * area * dp / (dp * dp + dp_lam * dp_lam) ** 0.25


@njit(cache=True)
def bulk_modulus(p, beta_liquid, air):
    """Effective bulk modulus with isothermal free air (volume share `air` at 1 atm)."""
    pabs = max(p + P_ATM, 1.0e4)
    return 1.0 / (1.0 / beta_liquid + air * P_ATM / (pabs * pabs))


@njit(cache=True)
def gravity_shape(xi):
    """Gravity load against extension over the stroke share xi, 1 at mid-stroke.

    The boom angle runs from -34 to +52 degrees over the stroke (the load's arm follows its
    cosine) and the cylinder's own arm is longest near mid-stroke.
    """
    arm_load = math.cos(-0.6 + 1.5 * xi) / math.cos(0.15)
    arm_cyl = (0.85 + 0.3 * math.sin(math.pi * xi)) / 1.15
    return arm_load / arm_cyl


@njit(cache=True)
def valve_flows(p, u, pP, pA, pB, visc_ratio, fault, sev):
    """Flows P->A, A->T, P->B, B->T [m^3/s] at spool position u."""
    kv = p[I_KV]
    dpl = p[I_DPL] * visc_ratio
    wear = 0.0
    if fault == SPOOL_WEAR:
        wear = SPOOL_WEAR_AREA * sev * max(0.0, 1.0 - abs(u) / SPOOL_WEAR_REACH)
    gl = p[I_VLEAK] / visc_ratio  # clearance leakage of a land, laminar
    pt = p[I_PT]
    a_pa = opening(u, p[I_OVP], p[I_AEXP]) + wear
    a_at = opening(-u, p[I_OVT], p[I_AEXP]) + wear
    a_pb = opening(-u, p[I_OVP], p[I_AEXP]) + wear
    a_bt = opening(u, p[I_OVT], p[I_AEXP]) + wear
    q_pa = orifice(kv, a_pa, pP - pA, dpl) + gl * (pP - pA)
    q_at = orifice(kv, a_at, pA - pt, dpl) + gl * (pA - pt)
    q_pb = orifice(kv, a_pb, pP - pB, dpl) + gl * (pP - pB)
    q_bt = orifice(kv, a_bt, pB - pt, dpl) + gl * (pB - pt)
    return q_pa, q_at, q_pb, q_bt


@njit(cache=True)
def pump_flow(p, s, disp_cmd, speed_rpm, visc_ratio, t):
    """Pump outlet flow [m^3/s] (geometric with ripple, less case leakage) and eps target."""
    n = speed_rpm / 60.0
    ripple = 1.0 + p[I_RIP] * math.sin(2.0 * math.pi * 9.0 * n * t)
    q_geo = s[EPS] * p[I_DISP] * n * ripple
    q_out = q_geo - p[I_PLEAK] / visc_ratio * max(s[PP], 0.0)
    comp = (p[I_CFU] - s[PP]) / (p[I_CFU] - p[I_CCR])
    eps_target = disp_cmd * min(max(comp, 0.0), 1.0)
    return q_out, eps_target


@njit(cache=True)
def friction(p, v, pA, pB, a_cap, a_ann, visc_ratio):
    """Stribeck friction with seal drag growing with pressure; viscous part follows viscosity."""
    fc = p[I_COUL] + p[I_SEAL] * (abs(pA) * a_cap + abs(pB) * a_ann)
    fs = p[I_STRB] * fc
    vr = v / p[I_VSTR]
    return (fc + (fs - fc) * math.exp(-vr * vr)) * math.tanh(v / 1e-3) + p[I_VISC] * (
        1.0 / visc_ratio
    ) ** 0.3 * v


@njit(cache=True)
def derivatives(p, s, uc, disp_cmd, speed, visc_ratio, fault, sev, payload, t, out):
    """Time derivative of the state s into out."""
    a_cap = math.pi / 4.0 * p[I_BORE] ** 2
    a_ann = a_cap - math.pi / 4.0 * p[I_ROD] ** 2
    stroke = p[I_STROKE]
    x, v, pA, pB, pP = s[X], s[V], s[PA], s[PB], s[PP]
    q_pa, q_at, q_pb, q_bt = valve_flows(p, s[U], pP, pA, pB, visc_ratio, fault, sev)
    q_ab = 0.0
    if fault == PISTON_WEAR:
        q_ab = PISTON_LEAK_MAX * sev / visc_ratio * (pA - pB)
    q_out, eps_target = pump_flow(p, s, disp_cmd, speed, visc_ratio, t)
    q_rated = p[I_DISP] * 2200.0 / 60.0
    q_rel = q_rated * max(pP - p[I_RCR], 0.0) / (p[I_RFU] - p[I_RCR])
    va = p[I_V0] + a_cap * min(max(x, 0.0), stroke)
    vb = p[I_V0] + a_ann * (stroke - min(max(x, 0.0), stroke))
    out[PA] = bulk_modulus(pA, p[I_BOIL], p[I_AIR]) / va * (q_pa - q_at - a_cap * v - q_ab)
    out[PB] = bulk_modulus(pB, p[I_BOIL], p[I_AIR]) / vb * (q_pb - q_bt + a_ann * v + q_ab)
    out[PP] = bulk_modulus(pP, p[I_BLINE], p[I_AIR]) / p[I_VLINE] * (q_out - q_pa - q_pb - q_rel)
    force = pA * a_cap - pB * a_ann - payload * p[I_GRAV] * gravity_shape(x / stroke)
    force -= friction(p, v, pA, pB, a_cap, a_ann, visc_ratio)
    if x < 0.0:
        force -= p[I_STOPK] * x + p[I_STOPC] * min(v, 0.0)
    elif x > stroke:
        force -= p[I_STOPK] * (x - stroke) + p[I_STOPC] * max(v, 0.0)
    out[X] = v
    out[V] = force / (payload * p[I_MASS])
    out[EPS] = (eps_target - s[EPS]) / p[I_TAU]
    wn = p[I_WN]
    out[U] = s[DU]
    out[DU] = wn * wn * (uc - s[U]) - 2.0 * p[I_ZETA] * wn * s[DU]
    out[QS] = (q_out - s[QS]) / FLOW_SENSOR_TAU_S


@njit(cache=True)
def _limit(s, u_max):
    """Cavitation floor on the pressures, the spool's stops."""
    for k in (PA, PB, PP):
        if s[k] < P_VAPOUR:
            s[k] = P_VAPOUR
    if s[U] > u_max:
        s[U] = u_max
        s[DU] = min(s[DU], 0.0)
    elif s[U] < -u_max:
        s[U] = -u_max
        s[DU] = max(s[DU], 0.0)


@njit(cache=True)
def run_kernel(p, s, t0, spool, disp, speed, temp, sev, fault, payload, out):
    """Integrate from state s over len(spool) samples; out[k] is the state after sample k."""
    k1 = np.empty(N_STATE)
    k2 = np.empty(N_STATE)
    k3 = np.empty(N_STATE)
    k4 = np.empty(N_STATE)
    tmp = np.empty(N_STATE)
    h = SAMPLE_S / SUBSTEPS
    a, b = _walther(p[I_NU40], p[I_NU100])
    for k in range(spool.shape[0]):
        nu = 10.0 ** (10.0 ** (a - b * math.log10(temp[k] + 273.15))) - 0.7
        vr = p[I_NU40] / nu  # > 1 when the oil is warmer (thinner) than 40 degC
        sv = sev[k]
        u_max = 1.0 - SPOOL_STROKE_LOSS * sv if fault == SPOOL_STROKE else 1.0
        uc = min(max(spool[k], -u_max), u_max)
        for j in range(SUBSTEPS):
            t = t0 + k * SAMPLE_S + j * h
            derivatives(p, s, uc, disp[k], speed[k], vr, fault, sv, payload, t, k1)
            tmp[:] = s + 0.5 * h * k1
            derivatives(p, tmp, uc, disp[k], speed[k], vr, fault, sv, payload, t + h / 2, k2)
            tmp[:] = s + 0.5 * h * k2
            derivatives(p, tmp, uc, disp[k], speed[k], vr, fault, sv, payload, t + h / 2, k3)
            tmp[:] = s + h * k3
            derivatives(p, tmp, uc, disp[k], speed[k], vr, fault, sv, payload, t + h, k4)
            s += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            _limit(s, u_max)
        out[k, :] = s


@njit(cache=True)
def _walther(nu40, nu100):
    w40 = math.log10(math.log10(nu40 + 0.7))
    w100 = math.log10(math.log10(nu100 + 0.7))
    b = (w40 - w100) / (math.log10(373.15) - math.log10(313.15))
    return w40 + b * math.log10(313.15), b


def initial_state(p: np.ndarray, x0_m: float, payload: float) -> np.ndarray:
    """A boom at rest at x0_m, the pump at its compensator's standby, pressures balanced."""
    s = np.zeros(N_STATE)
    a_cap = np.pi / 4 * p[IDX["bore_m"]] ** 2
    s[X] = x0_m
    s[PB] = p[IDX["tank_pa"]]
    a_ann = a_cap - np.pi / 4 * p[IDX["rod_m"]] ** 2
    s[PA] = (
        payload * p[IDX["gravity_n"]] * gravity_shape(x0_m / p[IDX["stroke_m"]]) + s[PB] * a_ann
    ) / a_cap
    s[PP] = p[IDX["comp_full_pa"]]
    return s


def visc_ratio(p: np.ndarray, temp_c: float) -> float:
    """nu(40 degC) / nu(temp_c): the factor laminar leakage grows by."""
    nu = viscosity_cst(temp_c, p[IDX["nu40_cst"]], p[IDX["nu100_cst"]])
    return float(p[IDX["nu40_cst"]] / nu)


def simulate(p, s, t0, spool, disp, speed, temp, sev, fault: str, payload: float):
    """Run the plant over the sample arrays from state s (updated in place); states per sample."""
    out = np.empty((len(spool), N_STATE))
    run_kernel(
        p,
        s,
        float(t0),
        np.ascontiguousarray(spool, dtype=np.float64),
        np.ascontiguousarray(disp, dtype=np.float64),
        np.ascontiguousarray(speed, dtype=np.float64),
        np.ascontiguousarray(temp, dtype=np.float64),
        np.ascontiguousarray(sev, dtype=np.float64),
        FAULTS[fault],
        float(payload),
        out,
    )
    return out
