"""The fourth plant's physics: one boom loop integrated in numba (SI units inside).

Parameters travel in one float64 vector `p`, indexed by the constants below (numba reads
module-level ints as compile-time constants). States:

    0 xs   main spool position (fraction of the 5 mm stroke, + = P->A, B->T)
    1 vs   main spool velocity (1/s)
    2 isol solenoid force as a fraction of full stroke (the current loop's lag)
    3 alpha swashplate angle (fraction of full displacement)
    4 cc   compensator spool opening (0 closed .. 1 fully destroking)
    5 vc   compensator spool velocity (1/s)
    6 PP   pump line pressure (Pa gauge)
    7 pA   cap chamber pressure (Pa)     8 pB rod chamber pressure (Pa)
    9 x1   piston and rod position (m)   10 v1 its velocity (m/s)
    11 x2  boom, seen at the rod (m)     12 v2 its velocity (m/s)
    13 we  engine speed (rad/s)          14 tf governor's fuel torque (N m)
    15 theta crank angle (rad, for the firing ripple)
    16 T   oil temperature (degC)
    17-19 free air share in A, B, pump line (0..1 of the air content at 1 atm)
    20-22 slow (viscoelastic) hose volume on A, B, pump line (m^3)
    23 pT  return line pressure (Pa)
"""

from __future__ import annotations

import numba
import numpy as np

N_STATES = 24

# --- parameter vector layout ---------------------------------------------------------
RHO = 0  # oil density kg/m^3
BETA0 = 1  # oil bulk modulus at 100 bar (Pa)
WAL_A = 2  # Walther constants of the oil: log10(log10(nu_cSt + 0.7)) = A - B log10(T_K)
WAL_B = 3
MU_REF = 4  # dynamic viscosity of the reference oil (VG46) at 40 degC (Pa s)
SP_WN = 5  # main spool natural frequency (rad/s)
SP_ZETA = 6
SP_TSOL = 7  # solenoid current-loop lag (s)
SP_SLOW_TAU = 8  # >0: pilot-flow-limited spool (first-order time constant, s)
SP_SLOW_VMAX = 9  # its velocity limit (stroke fractions per s)
STROKE_S = 10  # spool stroke (m)
LAP = 11  # overlap (m)
NOTCH_S = 12  # share of the stroke metered by the V notches
K_FULL_PA = 13  # full-stroke area of P->A (m^2), and the other edges
K_FULL_PB = 14
K_FULL_AT = 15
K_FULL_BT = 16
CD = 17  # turbulent discharge coefficient
LAM_CRIT = 18  # critical flow number of the Cd law
DP_REG = 19  # regularisation pressure of the sqrt (Pa)
CLEAR_G = 20  # radial clearance leak: pi d c^3 / 12 at ... (m^4), divided by mu and length
CLEAR_L0 = 21  # land length at zero cover (m)
D_MAX = 22  # pump max displacement (m^3/rad)
PC_START = 23  # compensator starts destroking (Pa)
PC_FULL = 24  # compensator fully destroked (Pa)
PC_WN = 25  # compensator spool natural frequency (rad/s)
PC_ZETA = 26
SV_TAU = 27  # swashplate servo time constant (s)
SV_RATE = 28  # swashplate servo rate limit (full strokes per s)
SLIP40 = 29  # pump slip, laminar (m^3/s/Pa) with the reference oil at 40 degC
WORN_K = 30  # worn pump's turbulent leak (m^3/s/sqrt(Pa))
RELIEF_CRACK = 31
RELIEF_FULL = 32
RELIEF_Q = 33  # relief flow at full pressure (m^3/s)
V_PUMP = 34  # pump line volume (m^3)
A_CAP = 35
A_ROD = 36
STROKE = 37  # cylinder stroke (m)
V_DEAD_A = 38
V_DEAD_B = 39
K_LINE = 40  # cylinder line restriction, turbulent (m^3/s/sqrt(Pa))
K_CUSH = 41  # cushion orifice (m^3/s/sqrt(Pa))
L_CUSH = 42  # cushion length (m)
M1 = 43  # piston + rod mass (kg)
M2 = 44  # boom mass at the rod (kg)
K_STRUCT = 45  # boom structure stiffness at the rod (N/m)
C_STRUCT = 46
C_VISC = 47  # viscous friction (N s/m) with the reference oil at 40 degC
VISC_SHARE = 48  # share of the viscous friction that follows the oil's viscosity
F_GRAV = 49  # gravity load at the reference pose (N)
LOAD_SPAN = 50  # pose effect: boom angle span over the stroke (rad); 0: constant load
LOAD_THETA0 = 51  # boom angle at mid stroke (rad)
FR_C0 = 52  # seal friction at zero pressure (N)
FR_KP = 53  # seal friction per Pa of the higher chamber pressure (N/Pa)
FR_STATIC = 54  # breakaway over sliding friction (ratio)
FR_VS = 55  # Stribeck velocity (m/s)
FR_VREG = 56  # regularisation velocity (m/s)
K_STOP = 57
C_STOP = 58
LEAK_AB_K = 59  # scored piston seal, turbulent (m^3/s/sqrt(Pa))
LEAK_AT_K = 60  # port relief on A leaking to tank, turbulent
AC_K = 61  # anti-cavitation checks (m^3/s/sqrt(Pa))
AC_CRACK = 62
FILTER_R40 = 63  # return filter, laminar (Pa per m^3/s) with the reference oil at 40 degC
RETURN_KT = 64  # return line turbulent drop (Pa per (m^3/s)^2)
RETURN_TAU = 65  # return line lag (s)
AIR_EPS = 66  # free air at 1 atm, volume share of the oil
AIR_TAU_D = 67  # dissolution time constant (s)
AIR_TAU_R = 68  # release time constant (s)
AIR_BUNSEN = 69  # Bunsen coefficient (volume of air dissolvable per volume per atm)
HOSE_CF = 70  # hose compliance, instant part (m^3/Pa) per cylinder line
HOSE_CS = 71  # hose compliance, creeping part (m^3/Pa) per cylinder line
HOSE_TAU = 72  # hose creep time constant (s)
HOSE_PUMP_SHARE = 73  # the pump line's hose compliance over a cylinder line's
J_ENG = 74  # engine and pump inertia (kg m^2)
W_NOLOAD = 75  # governor no-load speed (rad/s)
W_FULLLOAD = 76  # governor speed at rated torque (rad/s)
T_RATED = 77
GOV_TAU = 78
T_PARASITIC = 79
ETA_HM = 80  # pump hydro-mechanical efficiency
RIPPLE = 81  # firing torque ripple amplitude over mean torque
C_TH = 82  # thermal capacity of the oil circuit (J/K)
HA0 = 83  # heat loss without the cooler (W/K)
HA_COOL = 84  # cooler (W/K, fully open)
T_THERMO = 85  # thermostat opens (degC), fully open 5 K above
T_AMB = 86
F_PER_AMP = 87  # periodic force on the boom (N)
F_PER_HZ = 88
F_PER_PHASE = 89
B_NOTCH_BLOCK = 90  # share of the P->A notch area a lodged chip blocks
PC_LEAD = 91  # compensator's dynamic pressure feedback (s)
N_PARAMS = 92

P_ATM = 101325.0


@numba.njit(cache=True)
def viscosity_cst(p, temp_c):
    """Kinematic viscosity (cSt) by Walther's equation (ASTM D341)."""
    t_k = temp_c + 273.15
    return 10.0 ** (10.0 ** (p[WAL_A] - p[WAL_B] * np.log10(t_k))) - 0.7


@numba.njit(cache=True)
def notch_area(p, opening, a_full):
    """Metering area of an edge opened by `opening` metres past its cover: two V notches
    (area ~ opening^2) over the first NOTCH_S of the stroke, then the full port (linear),
    continuous in area and slope; a_full at the full zero-lap stroke."""
    if opening <= 0.0:
        return 0.0
    s = opening / p[STROKE_S]
    sn = p[NOTCH_S]
    g = s * s / (sn * (2.0 - sn)) if s < sn else (2.0 * s - sn) / (2.0 - sn)
    return a_full * g


@numba.njit(cache=True)
def edge_flow(p, dp, opening, a_full, nu_m2s, k_series):
    """Flow (m^3/s) from high to low through a metering edge: Cd rising with the flow
    number lambda = D_h / nu sqrt(2 dp / rho) (Cd = Cd_inf tanh(2 lambda / lambda_crit),
    Merritt's laminar-to-turbulent form), in series with a line restriction; below the
    cover, laminar leakage through the radial clearance over the covered land."""
    a = notch_area(p, opening, a_full)
    root = dp / (dp * dp + p[DP_REG] * p[DP_REG]) ** 0.25
    mu = nu_m2s * p[RHO]
    if a <= 0.0:
        cover = -opening if opening < 0.0 else 0.0
        return p[CLEAR_G] * dp / (mu * (cover + p[CLEAR_L0]))
    dh = 1.4 * opening
    lam = dh / nu_m2s * np.sqrt(2.0 * abs(dp) / p[RHO])
    cd = p[CD] * np.tanh(2.0 * lam / p[LAM_CRIT]) + 1e-3
    kv = cd * a * np.sqrt(2.0 / p[RHO])
    if k_series > 0.0:
        kv = kv * k_series / np.sqrt(kv * kv + k_series * k_series)
    return kv * root


@numba.njit(cache=True)
def beta_oil(p, pr):
    """Tangent bulk modulus of the oil, rising with pressure (about 5.5 per unit)."""
    return p[BETA0] + 5.5 * (pr - 1e7)


@numba.njit(cache=True)
def chamber_capacity(p, pr, vol, air_free):
    """dV/dp of a volume of oil with its free air (isothermal), m^3/Pa."""
    pa = max(pr + P_ATM, 2e4)
    gas = p[AIR_EPS] * air_free * P_ATM / pa
    return vol / beta_oil(p, pr) + vol * gas / pa


@numba.njit(cache=True)
def air_rate(p, pr, f):
    """Change of the free air share: towards Henry's equilibrium, slowly when dissolving."""
    if p[AIR_EPS] <= 0.0:
        return 0.0
    extra = p[AIR_BUNSEN] * max(pr, 0.0) / P_ATM
    f_eq = min(max(1.0 - extra / p[AIR_EPS], 0.0), 1.0)
    tau = p[AIR_TAU_D] if f > f_eq else p[AIR_TAU_R]
    return (f_eq - f) / tau


@numba.njit(cache=True)
def gravity_force(p, x2):
    """Gravity load at the rod: constant, or following the boom's pose (cos of its angle)."""
    if p[LOAD_SPAN] == 0.0:
        return p[F_GRAV]
    th = p[LOAD_THETA0] + p[LOAD_SPAN] * (x2 / p[STROKE] - 0.5)
    return p[F_GRAV] * np.cos(th) / np.cos(p[LOAD_THETA0])


@numba.njit(cache=True)
def seal_friction(p, v, pa, pb):
    """Pressure-energised seal friction with a Stribeck breakaway, odd in v."""
    fc = p[FR_C0] + p[FR_KP] * max(pa, pb, 0.0)
    if fc <= 0.0:
        return 0.0
    f = fc * (1.0 + (p[FR_STATIC] - 1.0) * np.exp(-((v / p[FR_VS]) ** 2)))
    return f * np.tanh(v / p[FR_VREG])


@numba.njit(cache=True)
def cushion_k(p, dist):
    """Exit restriction of a chamber whose cushion spear is `dist` from its end."""
    if dist >= p[L_CUSH]:
        return p[K_LINE]
    s = max(dist, 0.0) / p[L_CUSH]
    return p[K_CUSH] + (p[K_LINE] - p[K_CUSH]) * s * s
