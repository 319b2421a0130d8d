"""The numba-compiled hydraulic loop: its right-hand side, integrated by the shared RK4
(``monitor.sim.rk4``).

Everything here is SI (Pa, m^3/s, m, kg, N, s).  Parameters travel as one float64 vector
(indices below; ``pack.py`` fills it) so the sim-to-real tool can vary any of them without
recompiling.  States: pump line pressure, chamber pressures, rod position and velocity,
spool position and velocity, pump displacement fraction and its rate.
"""

from __future__ import annotations

import math

import numpy as np

from monitor.jit import jit
from monitor.sim import rk4
from monitor.sim.laws import (
    capacitance,
    clip,
    disp_target,
    edge_corrections,
    flow_forced,
    force_corrections,
    leak,
    metering,
    orifice,
    pump_flow,
)

# --- parameter vector layout -------------------------------------------------------------
BETA, V_LINE, V0A, V0B, AA, AB, STROKE = 0, 1, 2, 3, 4, 5, 6
MASS, FGRAV, CVISC, KV, DP_LAM, PTANK, DISP_MAX = 7, 8, 9, 10, 11, 12, 13
COMP_ON, COMP_START, COMP_FULL, RELIEF_CRACK, RELIEF_GAIN, XREF = 14, 15, 16, 17, 18, 19
AIR_ON, AIR_ALPHA, AIR_N = 20, 21, 22
VISC_ON, LEAK_K, FRIC_SHARE = 23, 24, 25
FRIC_ON, FC, FS, VS = 26, 27, 28, 29
SPOOL_ON, WN, ZETA = 30, 31, 32
OVERLAP = 33
PUMPDYN_ON, TAU_PUMP = 34, 35
HOSE_ON, E_WALL = 36, 37
SLOPE = 38
V_EPS = 39
# Family members (issue 18): every default keeps the formulas above bit for bit.
PISTON_LEAK, VALVE_LEAK = 40, 41  # m^3/(s Pa) at 40 degC, laminar: divided by nu/nu40
STRIBECK_EXP = 42  # -, exp(-|v/vs|^e): 2 Gaussian (default), 1 exponential
CURV = 43  # N/m^2, gravity load curvature about XREF
AIR_LAW, AIR_PCRIT = 44, 45  # 0 free air (Simscape), 1 air dissolving up to AIR_PCRIT (Pa abs)
HOSE_C_LINE, HOSE_C_CYL = 46, 47  # m^3/Pa, hose law added_capacitance
PUMP_WN, PUMP_ZETA = 48, 49  # rad/s, -: pump law second_order (PUMP_WN 0: first order)
# 50-69: data-driven corrections (monitor/sim/corrections.py, the ``suggestion`` of an
# ``unexplained`` diagnosis).  Every one is zero in the nominal model, and a zero one
# leaves the simulation bit-identical (its arithmetic is skipped).
LEAK_PT_LIN, LEAK_PT_SQRT, LEAK_AT_LIN, LEAK_AT_SQRT = 50, 51, 52, 53
LEAK_BT_LIN, LEAK_BT_SQRT, LEAK_AB_LIN, LEAK_AB_SQRT = 54, 55, 56, 57
F_VEL, F_SIGN, F_POS, F_PER_COS, F_PER_SIN, F_PER_W = 58, 59, 60, 61, 62, 63
KV_PA_REL, KV_PB_REL, KV_AT_REL, KV_BT_REL = 64, 65, 66, 67
LEAK_AT_SQ, CORR_ON = 68, 69
NOTCH = 70  # -, share of the stroke metered through notches (0: linear edges)
FLOW_FORCE = 71  # 1/Pa, the spool's opening over (1 + this * the open edges' drops); 0: none
N_PARAMS = 72

# --- input columns (per input sample, linearly interpolated inside a step) ----------------
IN_SPOOL, IN_DISP, IN_SPEED_RPS, IN_VISC_RATIO, IN_LEAK, IN_STROKE_LIM, IN_UNDERLAP = range(7)
IN_TIME = 7  # the recording's time (s): a periodic correction is periodic in it
N_INPUTS = 8

# --- states ------------------------------------------------------------------------------
S_PP, S_PA, S_PB, S_X, S_V, S_XS, S_VS, S_DISP, S_DISP_RATE = range(9)
N_STATES = 9

# --- recorded outputs ----------------------------------------------------------------------
R_PP, R_PA, R_PB, R_QP, R_X, R_V, R_XS = range(7)
N_RECORD = 7


# The laws (``monitor.sim.laws``) and the readers below take scalars and tuples of
# parameters, never the parameter or state arrays: numba's inliner wraps every array
# argument in an atomic reference count increment and decrement, and with the arrays passed
# down, those took half of a step's time (2026-11-28: 520 -> 190 ns per RK4 step).  The
# larger laws are plain functions that LLVM inlines (the same code, bit for bit): numba's
# own inlining copies their IR into each of the four right-hand sides of a step, which made
# the kernel's first compile 37 CPU-s (now 10).


@jit(inline="always")
def _compliance(p: float, vol: float, hose_vol: float, hose_c: float, prm: np.ndarray) -> float:
    """Hydraulic capacitance dV/dp of a node (m^3/Pa) at gauge pressure p; with hoses, the
    walls' share of ``hose_vol`` and the hose's own capacitance ``hose_c``."""
    return capacitance(p, vol, hose_vol, hose_c, _oil(prm))


@jit(inline="always")
def _oil(prm: np.ndarray) -> tuple:
    """The oil's and the hoses' parameters ``capacitance`` reads."""
    return (
        prm[BETA],
        prm[AIR_ON],
        prm[AIR_N],
        prm[AIR_ALPHA],
        prm[AIR_LAW],
        prm[AIR_PCRIT],
        prm[HOSE_ON],
        prm[E_WALL],
    )


@jit(inline="always")
def _compensator(prm: np.ndarray) -> tuple:
    """The compensator's (on, start, full) pressures."""
    return prm[COMP_ON], prm[COMP_START], prm[COMP_FULL]


@jit(inline="always")
def _pump(prm: np.ndarray) -> tuple:
    """The pump's (dynamics on, displacement, viscosity on, leakage coefficient)."""
    return prm[PUMPDYN_ON], prm[DISP_MAX], prm[VISC_ON], prm[LEAK_K]


@jit(inline="always")
def _force_terms(prm: np.ndarray) -> tuple:
    """The correction forces' coefficients ``force_corrections`` reads."""
    return (
        prm[F_POS],
        prm[XREF],
        prm[F_PER_COS],
        prm[F_PER_SIN],
        prm[F_PER_W],
        prm[F_VEL],
        prm[F_SIGN],
        prm[V_EPS],
    )


@jit(inline="always")
def rhs(y: np.ndarray, u: np.ndarray, prm: np.ndarray, dy: np.ndarray) -> float:
    """Write dy/dt into ``dy``; return the pump outlet flow QP in m^3/s."""
    # The inputs read at once, before any branch (see the helpers' note above).
    spool_cmd, lim, ul, k_il = u[IN_SPOOL], u[IN_STROKE_LIM], u[IN_UNDERLAP], u[IN_LEAK]
    vr_in, disp_cmd, speed_rps, t_s = u[IN_VISC_RATIO], u[IN_DISP], u[IN_SPEED_RPS], u[IN_TIME]
    pp = max(y[S_PP], 0.0)
    pa = max(y[S_PA], 0.0)
    pb = max(y[S_PB], 0.0)
    x = y[S_X]
    v = y[S_V]
    ptank = prm[PTANK]

    # Spool: follows the command, or a second-order response; mechanically limited stroke.
    if prm[SPOOL_ON] > 0.0:
        xs = y[S_XS]
        wn = prm[WN]
        dy[S_XS] = y[S_VS]
        dy[S_VS] = wn * wn * (spool_cmd - xs) - 2.0 * prm[ZETA] * wn * y[S_VS]
    else:
        xs = spool_cmd
        dy[S_XS] = 0.0
        dy[S_VS] = 0.0
    xs = clip(xs, -lim, lim)
    if prm[FLOW_FORCE] > 0.0:
        xs = flow_forced(xs, pp, pa, pb, ptank, prm[FLOW_FORCE])
    ov = prm[OVERLAP]
    mag = max(abs(xs) - ov, 0.0) / (1.0 - ov)
    if prm[NOTCH] > 0.0:
        mag = metering(mag, prm[NOTCH])
    s = mag if xs >= 0.0 else -mag
    o_pos = clip(s + ul, 0.0, 1.0)  # P->A and B->T
    o_neg = clip(-s + ul, 0.0, 1.0)  # P->B and A->T
    kv = prm[KV]
    dpl = prm[DP_LAM]
    q_pa = orifice(kv * o_pos, pp - pa, dpl)
    q_bt = orifice(kv * o_pos, pb - ptank, dpl)
    q_pb = orifice(kv * o_neg, pp - pb, dpl)
    q_at = orifice(kv * o_neg, pa - ptank, dpl)
    q_il = k_il * (pa - pb)
    if prm[VISC_ON] > 0.0 and (prm[PISTON_LEAK] > 0.0 or prm[VALVE_LEAK] > 0.0):
        # Thin oil leaks across the piston seal and the spool's clearances too (laminar).
        vr = vr_in
        q_il += prm[PISTON_LEAK] * (pa - pb) / vr
        kc = prm[VALVE_LEAK] / vr
        q_pa += kc * (pp - pa)
        q_pb += kc * (pp - pb)
        q_at += kc * (pa - ptank)
        q_bt += kc * (pb - ptank)
    if prm[CORR_ON] > 0.0:
        rel = (prm[KV_PA_REL], prm[KV_BT_REL], prm[KV_PB_REL], prm[KV_AT_REL])
        q_pa, q_bt, q_pb, q_at = edge_corrections(q_pa, q_bt, q_pb, q_at, rel)
        q_il += leak(prm[LEAK_AB_LIN], prm[LEAK_AB_SQRT], pa - pb, dpl)
        q_at += leak(prm[LEAK_AT_LIN], prm[LEAK_AT_SQRT], pa - ptank, dpl)
        if prm[LEAK_AT_SQ] != 0.0:
            q_at += prm[LEAK_AT_SQ] * (pa - ptank) * abs(pa - ptank)
        q_bt += leak(prm[LEAK_BT_LIN], prm[LEAK_BT_SQRT], pb - ptank, dpl)

    # Pump: displacement command times the compensator's destroke, optionally lagged.
    target = disp_target(pp, disp_cmd, _compensator(prm))
    dy[S_DISP_RATE] = 0.0
    if prm[PUMPDYN_ON] > 0.0 and prm[PUMP_WN] > 0.0:
        wp, rate = prm[PUMP_WN], y[S_DISP_RATE]
        dy[S_DISP] = rate
        dy[S_DISP_RATE] = wp * wp * (target - y[S_DISP]) - 2.0 * prm[PUMP_ZETA] * wp * rate
    elif prm[PUMPDYN_ON] > 0.0:
        dy[S_DISP] = (target - y[S_DISP]) / prm[TAU_PUMP]
    else:
        dy[S_DISP] = 0.0
    qp = pump_flow(y[S_PP], y[S_DISP], speed_rps, vr_in, target, _pump(prm))
    visc_ratio = vr_in if prm[VISC_ON] > 0.0 else 1.0
    q_relief = prm[RELIEF_GAIN] * max(pp - prm[RELIEF_CRACK], 0.0)
    if prm[CORR_ON] > 0.0:
        q_relief += leak(prm[LEAK_PT_LIN], prm[LEAK_PT_SQRT], pp - ptank, dpl)
    oil = _oil(prm)
    c_line = capacitance(pp, prm[V_LINE], prm[V_LINE], prm[HOSE_C_LINE], oil)
    dy[S_PP] = (qp - q_relief - q_pa - q_pb) / c_line

    # Rod: pressure force against gravity (optionally position dependent) and friction.
    f_hyd = pa * prm[AA] - pb * prm[AB]
    dx = x - prm[XREF]
    f_grav = prm[FGRAV] + prm[SLOPE] * dx + prm[CURV] * dx * dx
    c = prm[CVISC]
    if prm[VISC_ON] > 0.0:
        c *= 1.0 - prm[FRIC_SHARE] + prm[FRIC_SHARE] * visc_ratio
    f_fric = c * v
    if prm[FRIC_ON] > 0.0:
        r = v / prm[VS]
        e = prm[STRIBECK_EXP]
        decay = math.exp(-r * r) if e == 2.0 else math.exp(-(abs(r) ** e))
        f_fric += (prm[FC] + (prm[FS] - prm[FC]) * decay) * math.tanh(v / prm[V_EPS])
    if prm[CORR_ON] > 0.0:
        f_grav, f_fric = force_corrections(f_grav, f_fric, x, v, t_s, _force_terms(prm))
    drive = f_hyd - f_grav
    stroke = prm[STROKE]
    # End stops: the rod rests on a stop while the net drive presses it there.
    if (x <= 0.0 and v <= 0.0 and drive <= 0.0) or (x >= stroke and v >= 0.0 and drive >= 0.0):
        v = 0.0
        dy[S_V] = 0.0
    else:
        dy[S_V] = (drive - f_fric) / prm[MASS]
    dy[S_X] = v

    vol_a = prm[V0A] + prm[AA] * x
    vol_b = prm[V0B] + prm[AB] * (stroke - x)
    c_a = capacitance(pa, vol_a, prm[V0A], prm[HOSE_C_CYL], oil)
    c_b = capacitance(pb, vol_b, prm[V0B], prm[HOSE_C_CYL], oil)
    dy[S_PA] = (q_pa - q_at - q_il - prm[AA] * v) / c_a
    dy[S_PB] = (q_pb - q_bt + q_il + prm[AB] * v) / c_b
    return qp


@jit(inline="always")
def _project(y: np.ndarray, prm: np.ndarray) -> None:
    """Keep the state physical after a step: no negative pressure, rod within its stops."""
    stroke = prm[STROKE]
    for i in (S_PP, S_PA, S_PB):
        if y[i] < 0.0:
            y[i] = 0.0
    if y[S_X] < 0.0:
        y[S_X] = 0.0
        y[S_V] = max(y[S_V], 0.0)
    elif y[S_X] > stroke:
        y[S_X] = stroke
        y[S_V] = min(y[S_V], 0.0)


@jit(inline="always")
def _derivative(
    y: np.ndarray, u: np.ndarray, prm: np.ndarray, dy: np.ndarray, aux: np.ndarray
) -> None:
    """``rhs`` in the shared integrator's form (the loop needs no auxiliary outputs)."""
    rhs(y, u, prm, dy)


@jit
def integrate(
    y0: np.ndarray,
    inputs: np.ndarray,
    n_sub: int,
    input_dt: float,
    prm: np.ndarray,
    record_every: int,
) -> np.ndarray:
    """Classic RK4 at h = input_dt / n_sub, inputs linear between their samples
    (``monitor.sim.rk4.integrate``).

    Returns the recorded outputs (rows every ``record_every`` steps, the first at t=0).
    """
    return rk4.integrate(
        _derivative, _project, _record, N_RECORD, 0, y0, inputs, n_sub, input_dt, prm, record_every
    )


@jit(inline="always")
def _record(
    rec: np.ndarray,
    r: int,
    y: np.ndarray,
    u: np.ndarray,
    prm: np.ndarray,
    scratch: np.ndarray,
    aux: np.ndarray,
) -> None:
    # QP alone, not a whole right-hand side (a record every few steps made that 5-12 %).
    target = disp_target(max(y[S_PP], 0.0), u[IN_DISP], _compensator(prm))
    qp = pump_flow(y[S_PP], y[S_DISP], u[IN_SPEED_RPS], u[IN_VISC_RATIO], target, _pump(prm))
    rec[r, R_PP] = y[S_PP]
    rec[r, R_PA] = y[S_PA]
    rec[r, R_PB] = y[S_PB]
    rec[r, R_QP] = qp
    rec[r, R_X] = y[S_X]
    rec[r, R_V] = y[S_V]
    xs = y[S_XS] if prm[SPOOL_ON] > 0.0 else u[IN_SPOOL]
    rec[r, R_XS] = clip(xs, -u[IN_STROKE_LIM], u[IN_STROKE_LIM])
