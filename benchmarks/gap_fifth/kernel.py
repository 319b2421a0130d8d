"""The fifth plant's equations of motion (numba, fixed-step RK4, SI units).

States: engine speed and governor integral; swashplate (share of full displacement), the
pump regulator's spool and what it senses (load-sensing pump: the margin spool and the LS
line; pressure-compensated pump: the compensator spool and the pump pressure through its
sensing passage); pump line, chamber A and B pressures (each chamber merged with its hose;
the readings sit at the valve ports, a line drop away); solenoid force and spool position
and speed (share of full stroke); boom angle and rate (the included angle at the boom
pivot); the LuGre bristle; the creep volumes of the hose walls; the return-line pressure;
the pump's delivered volume (what a gear flow meter counts); and, for the compensated pump
only, the control piston's pressure, the swashplate's rate and the displacement stop.

Inputs (one row a millisecond): spool command (-1..1), displacement limit (0..1), engine
speed set point (rad/s), oil viscosity (cSt), load torque of the engine's other consumers
(N m), time (s, for the periodic rod force of one fault).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from benchmarks.gap_fifth import params as pr

N_STATES = 22
(S_WE, S_GI, S_ALPHA, S_YMAR, S_PLS, S_PP, S_PA, S_PB, S_ISOL, S_XS, S_VS, S_PSI, S_WB,
 S_Z, S_VEA, S_VEB, S_VEP, S_PT, S_QCUM, S_PC, S_VSW, S_LIM) = range(N_STATES)  # fmt: skip
OUT_NAMES = ("pp", "pa_port", "pb_port", "q_out", "q_cum", "stroke", "speed_rad_s",
             "pa", "pb", "alpha", "spool", "rod_v")  # fmt: skip
P_ATM = 1.013e5
STOP_RELAX_S = 0.002  # a swashplate on a stop loses its own rate within a few ms


@njit(cache=True)
def _capacitance(p: np.ndarray, pa: float, vol: float) -> float:
    """V / beta_eff: oil whose tangent modulus rises with pressure, and polytropic free air."""
    p_abs = max(pa + P_ATM, 2.0e3)
    beta_l = p[pr.P_BETA0_PA] + p[pr.P_BETA_SLOPE] * max(pa, 0.0)
    x0 = p[pr.P_AIR_FRAC]
    n = p[pr.P_AIR_POLY_N]
    g = x0 / (1.0 - x0) * (P_ATM / p_abs) ** (1.0 / n)
    beta = (1.0 + g) / (1.0 / beta_l + g / (n * p_abs))
    return vol / beta


@njit(cache=True)
def _edge(p: np.ndarray, u: float, dp: float, nu_m2s: float) -> float:
    """Flow through round metering holes opened by u (m): Cd rises from laminar to turbulent."""
    if u <= 0.0:
        return 0.0
    r = 0.5 * p[pr.P_HOLE_D_M]
    uu = min(u, 2.0 * r)
    seg = r * r * math.acos((r - uu) / r) - (r - uu) * math.sqrt(max(2.0 * r * uu - uu * uu, 0.0))
    area = p[pr.P_HOLE_N] * seg
    vel = math.sqrt(2.0 * abs(dp) / p[pr.P_RHO])
    cd = p[pr.P_CD_INF] * math.tanh(2.0 * uu * vel / (nu_m2s * p[pr.P_LAMBDA_C]) + 1e-12)
    q = cd * area * vel
    return q if dp >= 0.0 else -q


@njit(cache=True)
def _geometry(p: np.ndarray, psi: float):
    """Cylinder stroke (m) and lever arm dl/dpsi (m) at the pivot's included angle psi."""
    a = p[pr.P_LINK_A_M]
    b = p[pr.P_LINK_B_M]
    length = math.sqrt(a * a + b * b - 2.0 * a * b * math.cos(psi))
    return length - p[pr.P_CYL_L0_M], a * b * math.sin(psi) / length


@njit(cache=True)
def _valve(p, y, nu_cst, out):
    """Metering flows P->A, A->T, P->B, B->T (m^3/s), their closing flow force (N), leaks."""
    nu = nu_cst * 1e-6
    xmax = p[pr.P_OVERLAP_M] + p[pr.P_HOLE_D_M]
    x = y[S_XS] * xmax
    u = abs(x) - p[pr.P_OVERLAP_M]
    pp, pa, pb, pt = y[S_PP], y[S_PA], y[S_PB], y[S_PT]
    leak = p[pr.P_CLEAR_LEAK_M3] / nu_cst
    q_pa = leak * (pp - pa)
    q_at = leak * (pa - pt)
    q_pb = leak * (pp - pb)
    q_bt = leak * (pb - pt)
    ff = 0.0
    if x > 0.0 and u > 0.0:
        q_pa += _edge(p, u, pp - pa, nu)
        q_bt += p[pr.P_EDGE_BT_SCALE] * _edge(p, u, pb - pt, nu)
        ff = abs(q_pa) * math.sqrt(0.5 * p[pr.P_RHO] * abs(pp - pa)) + abs(q_bt) * math.sqrt(
            0.5 * p[pr.P_RHO] * abs(pb - pt)
        )
    elif x < 0.0 and u > 0.0:
        q_pb += _edge(p, u, pp - pb, nu)
        q_at += _edge(p, u, pa - pt, nu)
        ff = abs(q_pb) * math.sqrt(0.5 * p[pr.P_RHO] * abs(pp - pb)) + abs(q_at) * math.sqrt(
            0.5 * p[pr.P_RHO] * abs(pa - pt)
        )
    out[0] = q_pa
    out[1] = q_at
    out[2] = q_pb
    out[3] = q_bt
    # steady flow force ~ 2 Cd Cv A dp cos(theta) = k Q sqrt(rho dp / 2) / Cd ... per edge
    out[4] = p[pr.P_FLOW_FORCE_K] * ff / p[pr.P_CD_INF]


@njit(cache=True)
def _pump(p, y, u, nu_cst, out):
    """Delivered flow (m^3/s), shaft torque (N m), relief flow (m^3/s)."""
    pp, pt = y[S_PP], y[S_PT]
    dp = max(pp - pt, 0.0)
    q_th = p[pr.P_DISP_MAX_M3] * y[S_ALPHA] * y[S_WE] / (2.0 * math.pi)
    slip = p[pr.P_SLIP_WILSON] / 60000.0 / 1e7 * (46.0 / nu_cst) * dp
    wear = p[pr.P_WEAR_LEAK_K] / 60000.0 * (dp / 1e7) ** 0.7
    out[0] = q_th - slip - wear
    out[1] = p[pr.P_DISP_MAX_M3] * y[S_ALPHA] * dp / (2.0 * math.pi) / 0.92
    span = p[pr.P_RELIEF_FULL_PA] - p[pr.P_RELIEF_CRACK_PA]
    out[2] = p[pr.P_RELIEF_Q_M3S] * min(max((pp - p[pr.P_RELIEF_CRACK_PA]) / span, 0.0), 1.0)


@njit(cache=True)
def _governor(p, y, u, dy):
    """The engine's isochronous PI governor: its torque (N m), limited."""
    e = u[2] - y[S_WE]
    t_eng = p[pr.P_GOV_KP] * e + y[S_GI]
    dy[S_GI] = p[pr.P_GOV_KI] * e
    if t_eng > p[pr.P_ENG_TMAX]:
        t_eng = p[pr.P_ENG_TMAX]
        dy[S_GI] = min(dy[S_GI], 0.0)
    elif t_eng < 0.0:
        t_eng = 0.0
        dy[S_GI] = max(dy[S_GI], 0.0)
    return t_eng


@njit(cache=True)
def _ls_control(p, y, u, dy):
    """Load-sensing margin spool, pressure cut-off and an integrating swashplate servo."""
    # load sensing: the opened work port's pressure, else the drained LS line
    xmax = p[pr.P_OVERLAP_M] + p[pr.P_HOLE_D_M]
    opening = abs(y[S_XS]) * xmax - p[pr.P_OVERLAP_M]
    target = y[S_PT]
    if opening > 0.0:
        target = y[S_PA] if y[S_XS] > 0.0 else y[S_PB]
    dy[S_PLS] = (target - y[S_PLS]) / p[pr.P_LS_TAU_S]
    err = (y[S_PP] - y[S_PLS] - p[pr.P_MARGIN_PA]) / p[pr.P_MARGIN_BAND_PA]
    dy[S_YMAR] = (min(max(err, -1.0), 1.0) - y[S_YMAR]) / p[pr.P_MARGIN_TAU_S]
    cut = min(max((y[S_PP] - p[pr.P_CUTOFF_PA]) / p[pr.P_CUTOFF_BAND_PA], 0.0), 1.0)
    ctl = max(y[S_YMAR], cut) if cut > 0.0 else y[S_YMAR]
    limit = min(u[1], p[pr.P_DISP_STOP])
    rate = -ctl / p[pr.P_SWASH_TAU_S]
    if y[S_ALPHA] > limit:
        rate = min(rate, -(y[S_ALPHA] - limit) / p[pr.P_SWASH_TAU_S] - 0.2)
    if (y[S_ALPHA] <= 0.0 and rate < 0.0) or (y[S_ALPHA] >= 1.0 and rate > 0.0):
        rate = 0.0
    dy[S_ALPHA] = rate


@njit(cache=True)
def _ctl_edge(p, area, dp):
    """A control edge's flow (m^3/s): turbulent, laminar below about half a bar."""
    return p[pr.P_CTL_CD] * area * math.sqrt(2.0 / p[pr.P_RHO]) * dp / math.sqrt(abs(dp) + 0.5e5)


@njit(cache=True)
def _pc_control(p, y, u, dy):
    """Compensator spool, control piston against the bias spring, swashplate and its
    displacement stop; returns the control flow taken from the pump line (m^3/s).

    The spool (a first-order lag) sees the pump pressure through a sensing passage against
    its spring: above the setting it opens the pump line to the control piston, below it
    vents the piston to the case; it is underlapped, so both edges bleed at null. The
    piston (its chamber compressible) pushes the swashplate towards zero displacement
    against a bias spring and with the pistons' own moment; the swashplate has mass and
    viscous damping, and rests on a stop that `PumpDispCmd` sets through a solenoid.
    """
    pp, pc, pt = y[S_PP], y[S_PC], y[S_PT]
    dy[S_PLS] = (pp - y[S_PLS]) / p[pr.P_COMP_SENSE_TAU_S]
    # the feedback spring: the swashplate's stroke towards zero loads the spool's spring
    null = p[pr.P_COMP_SET_PA] + p[pr.P_COMP_DROOP_PA] * (1.0 - y[S_ALPHA])
    aim = min(max((y[S_PLS] - null) / p[pr.P_COMP_BAND_PA], -1.0), 1.0)
    dy[S_YMAR] = (aim - y[S_YMAR]) / p[pr.P_COMP_TAU_S]
    area = p[pr.P_CTL_AREA_M2]
    lap = p[pr.P_COMP_UNDERLAP]
    a_in = area * p[pr.P_CTL_RESTRICT_IN] * max(y[S_YMAR] + lap, 0.0)
    a_vent = area * p[pr.P_CTL_RESTRICT_VENT] * max(lap - y[S_YMAR], 0.0)
    q_in = _ctl_edge(p, a_in, pp - pc)
    q_vent = _ctl_edge(p, a_vent, pc - pt)
    x_full = p[pr.P_CTL_STROKE_M]
    x = (1.0 - y[S_ALPHA]) * x_full  # the piston's travel from full displacement
    xdot = -y[S_VSW] * x_full
    a_cp = p[pr.P_CTL_PISTON_M2]
    c_ctl = _capacitance(p, pc, p[pr.P_CTL_DEAD_M3] + a_cp * x)
    dy[S_PC] = (q_in - q_vent - a_cp * xdot) / c_ctl
    if pc < -0.98e5 and dy[S_PC] < 0.0:
        dy[S_PC] = 0.0
    destroke = pc * a_cp + p[pr.P_SWASH_MOMENT_M2] * max(pp, 0.0)
    destroke -= p[pr.P_BIAS_F0_N] + p[pr.P_BIAS_K_N_M] * x + p[pr.P_SWASH_C_N_S_M] * xdot
    acc = -destroke / (p[pr.P_SWASH_MASS_KG] * x_full)  # swashplate, share/s^2
    dy[S_LIM] = (min(u[1], p[pr.P_DISP_STOP]) - y[S_LIM]) / p[pr.P_STOP_TAU_S]
    dy[S_ALPHA] = y[S_VSW]
    dy[S_VSW] = acc
    if y[S_ALPHA] >= y[S_LIM] and acc >= 0.0:  # held on the stop, riding with it
        dy[S_ALPHA] = dy[S_LIM]
        dy[S_VSW] = (dy[S_LIM] - y[S_VSW]) / STOP_RELAX_S
    elif y[S_ALPHA] <= 0.0 and acc <= 0.0:  # on the zero-displacement end
        dy[S_ALPHA] = 0.0
        dy[S_VSW] = -y[S_VSW] / STOP_RELAX_S
    return q_in


@njit(cache=True)
def _rod(p, y, u, dy, pa, pb):
    """Boom on its linkage: torque balance about the pivot, LuGre seal friction, end stops."""
    s, arm = _geometry(p, y[S_PSI])
    v = arm * y[S_WB]
    nu_ratio = u[3] / 46.0
    press_bar = (max(pa, 0.0) + max(pb, 0.0)) / 1e5
    fc = p[pr.P_FRIC_FC_N] + p[pr.P_FRIC_KP_N_PER_BAR] * press_bar
    fs = p[pr.P_FRIC_FS_N] + p[pr.P_FRIC_KP_N_PER_BAR] * press_bar
    g = fc + (fs - fc) * math.exp(-((v / p[pr.P_FRIC_VS]) ** 2))
    dz = v - p[pr.P_FRIC_SIGMA0] * abs(v) * y[S_Z] / max(g, 1e-3)
    f_fric = p[pr.P_FRIC_SIGMA0] * y[S_Z] + p[pr.P_FRIC_SIGMA1] * dz
    f_fric += p[pr.P_FRIC_C_NU] * nu_ratio**0.3 * v
    dy[S_Z] = dz
    f_stop = 0.0
    if s < 0.0:
        f_stop = max(-p[pr.P_STOP_K] * s - p[pr.P_STOP_C] * v, 0.0)
    elif s > p[pr.P_STROKE_M]:
        f_stop = min(-p[pr.P_STOP_K] * (s - p[pr.P_STROKE_M]) - p[pr.P_STOP_C] * v, 0.0)
    f_ext = p[pr.P_ROD_FORCE_AMP] * math.sin(2.0 * math.pi * p[pr.P_ROD_FORCE_HZ] * u[5])
    if p[pr.P_BAL_F0_N] != 0.0:
        squeeze = min(p[pr.P_STROKE_M] - s, 0.9 * p[pr.P_BAL_GAS_M])
        f_ext += p[pr.P_BAL_F0_N] * (p[pr.P_BAL_GAS_M] / (p[pr.P_BAL_GAS_M] - squeeze)) ** 1.3
    f_rod = pa * p[pr.P_AREA_A] - pb * p[pr.P_AREA_B] + f_stop - f_fric + f_ext
    theta = y[S_PSI] - p[pr.P_PSI_OFF_RAD]
    grav = p[pr.P_BOOM_MGL] * math.cos(theta)
    dy[S_PSI] = y[S_WB]
    dy[S_WB] = (arm * f_rod - grav) / p[pr.P_BOOM_J]
    return v, s


@njit(cache=True)
def _hose(p, y, dy, state, press, c_elastic):
    """Creep volume of a hose wall (standard linear solid); returns its rate (m^3/s)."""
    rate = (p[pr.P_HOSE_CREEP] * c_elastic * max(press, 0.0) - y[state]) / p[pr.P_HOSE_TAU_S]
    dy[state] = rate
    return rate


@njit(cache=True)
def _deriv(p, y, u, dy, work):
    """Every state's rate; work[0..] holds the flows the outputs need."""
    nu_cst = u[3]
    _valve(p, y, nu_cst, work)
    q_pa, q_at, q_pb, q_bt, f_flow = work[0], work[1], work[2], work[3], work[4]
    _pump(p, y, u, nu_cst, work[5:8])
    t_eng = _governor(p, y, u, dy)
    if p[pr.P_PUMP_PC] > 0.5:
        work[5] -= _pc_control(p, y, u, dy)  # the compensator draws its flow inside the pump
    else:
        _ls_control(p, y, u, dy)
    q_out, t_pump, q_rel = work[5], work[6], work[7]
    dy[S_WE] = (t_eng - t_pump - u[4]) / p[pr.P_ENG_INERTIA]
    pa, pb, pp, pt = y[S_PA], y[S_PB], y[S_PP], y[S_PT]
    v, s = _rod(p, y, u, dy, pa, pb)
    # spool: solenoid lag, spring-centred spool pushed back by the steady flow force
    dy[S_ISOL] = (u[0] - y[S_ISOL]) / p[pr.P_SOL_TAU_S]
    sign = 1.0 if y[S_XS] > 0.0 else -1.0
    aim = min(max(y[S_ISOL], -1.0), 1.0) - sign * f_flow / p[pr.P_SPRING_FULL_N]
    wn = p[pr.P_SPOOL_WN]
    dy[S_VS] = wn * wn * (aim - y[S_XS]) - 2.0 * p[pr.P_SPOOL_ZETA] * wn * y[S_VS]
    vmax = p[pr.P_SPOOL_VMAX]
    dy[S_XS] = min(max(y[S_VS], -vmax), vmax)
    if (y[S_XS] >= 1.0 and dy[S_XS] > 0.0) or (y[S_XS] <= -1.0 and dy[S_XS] < 0.0):
        dy[S_XS] = 0.0
    # leaks outside the valve (faults): piston seal A<->B, port relief A->tank
    q_ab = p[pr.P_SEAL_LEAK_AB] / 60000.0 * (pa - pb) / 1e7
    q_al = p[pr.P_PORT_LEAK_A] / 60000.0 * (max(pa - pt, 0.0) / 1e7) ** 0.8
    # pressures
    vol_a = p[pr.P_DEAD_A_M3] + p[pr.P_AREA_A] * s
    vol_b = p[pr.P_DEAD_B_M3] + p[pr.P_AREA_B] * (p[pr.P_STROKE_M] - s)
    c_a = _capacitance(p, pa, vol_a) + p[pr.P_HOSE_C_A]
    c_b = _capacitance(p, pb, vol_b) + p[pr.P_HOSE_C_B]
    c_p = _capacitance(p, pp, p[pr.P_VOL_P_M3]) + p[pr.P_HOSE_C_P]
    cr_a = _hose(p, y, dy, S_VEA, pa, p[pr.P_HOSE_C_A])
    cr_b = _hose(p, y, dy, S_VEB, pb, p[pr.P_HOSE_C_B])
    cr_p = _hose(p, y, dy, S_VEP, pp, p[pr.P_HOSE_C_P])
    dy[S_PA] = (q_pa - q_at - q_ab - q_al - p[pr.P_AREA_A] * v - cr_a) / c_a
    dy[S_PB] = (q_pb - q_bt + q_ab + p[pr.P_AREA_B] * v - cr_b) / c_b
    dy[S_PP] = (q_out - q_pa - q_pb - q_rel - cr_p) / c_p
    for k in (S_PA, S_PB, S_PP):
        if y[k] < -0.98e5 and dy[k] < 0.0:
            dy[k] = 0.0
    q_tank = q_at + q_bt + q_rel + q_al
    dy[S_PT] = (p[pr.P_TANK_P0_PA] + p[pr.P_TANK_K_PA_S2_M6] * q_tank * abs(q_tank) - pt) / p[
        pr.P_TANK_TAU_S
    ]
    dy[S_QCUM] = q_out
    work[8] = v
    work[9] = s


@njit(cache=True)
def integrate(p, y0, inputs, substeps):
    """RK4 with `substeps` steps a millisecond; one output row per input row (OUT_NAMES)."""
    n = inputs.shape[0]
    out = np.empty((n, len(OUT_NAMES)))
    y = y0.copy()
    k1 = np.empty(N_STATES)
    k2 = np.empty(N_STATES)
    k3 = np.empty(N_STATES)
    k4 = np.empty(N_STATES)
    tmp = np.empty(N_STATES)
    work = np.zeros(10)
    h = 1e-3 / substeps
    for i in range(n):
        u = inputs[i]
        for _ in range(substeps):
            _deriv(p, y, u, k1, work)
            for j in range(N_STATES):
                tmp[j] = y[j] + 0.5 * h * k1[j]
            _deriv(p, tmp, u, k2, work)
            for j in range(N_STATES):
                tmp[j] = y[j] + 0.5 * h * k2[j]
            _deriv(p, tmp, u, k3, work)
            for j in range(N_STATES):
                tmp[j] = y[j] + h * k3[j]
            _deriv(p, tmp, u, k4, work)
            for j in range(N_STATES):
                y[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
            top = y[S_LIM] if p[pr.P_PUMP_PC] > 0.5 else 1.0
            y[S_ALPHA] = min(max(y[S_ALPHA], 0.0), top)
            y[S_XS] = min(max(y[S_XS], -1.0), 1.0)
        _deriv(p, y, u, k1, work)
        q_ain = work[0] - work[1]
        q_bin = work[2] - work[3]
        nu = u[3]
        drop_a = p[pr.P_LINE_R_LAM] * nu * q_ain + p[pr.P_LINE_R_TURB] * q_ain * abs(q_ain)
        drop_b = p[pr.P_LINE_R_LAM] * nu * q_bin + p[pr.P_LINE_R_TURB] * q_bin * abs(q_bin)
        out[i, 0] = y[S_PP]
        out[i, 1] = y[S_PA] + drop_a
        out[i, 2] = y[S_PB] + drop_b
        out[i, 3] = work[5]
        out[i, 4] = y[S_QCUM]
        out[i, 5] = work[9]
        out[i, 6] = y[S_WE]
        out[i, 7] = y[S_PA]
        out[i, 8] = y[S_PB]
        out[i, 9] = y[S_ALPHA]
        out[i, 10] = y[S_XS]
        out[i, 11] = work[8]
    return out, y
