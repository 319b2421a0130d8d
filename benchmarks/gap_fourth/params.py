"""Nominal values of the fourth plant (the reference machine of docs/reference/contracts.md
with base dynamics of its own) and the machines' tolerance draws."""

from __future__ import annotations

import math

import numpy as np

from benchmarks.gap_fourth import plant as pl

LPM = 1.0 / 60000.0  # m^3/s per L/min
BAR = 1e5
RPM = 2.0 * math.pi / 60.0


def walther(nu40_cst: float, nu100_cst: float) -> tuple[float, float]:
    """Walther constants (A, B) through two viscosities: log log (nu + 0.7) = A - B log T."""
    y40 = math.log10(math.log10(nu40_cst + 0.7))
    y100 = math.log10(math.log10(nu100_cst + 0.7))
    l40, l100 = math.log10(313.15), math.log10(373.15)
    b = (y40 - y100) / (l100 - l40)
    return y40 + b * l40, b


def edge_area(q_lpm: float, dp_bar: float, cd: float, rho: float) -> float:
    """Area (m^2) passing q at dp with a turbulent discharge coefficient cd."""
    return q_lpm * LPM / (cd * math.sqrt(2.0 * dp_bar * BAR / rho))


def nominal() -> np.ndarray:
    """The nominal parameter vector (SI): the reference machine's values where the docs
    give them, this plant's own base dynamics around them."""
    p = np.zeros(pl.N_PARAMS)
    _oil_and_valve(p)
    _pump(p)
    _cylinder_and_boom(p)
    _engine_and_oil(p)
    return p


def _oil_and_valve(p: np.ndarray) -> None:
    p[pl.RHO] = 870.0
    p[pl.BETA0] = 1.5e9
    p[pl.WAL_A], p[pl.WAL_B] = walther(46.0, 6.8)
    p[pl.MU_REF] = 46e-6 * 870.0
    # proportional solenoid, pilot-operated main spool: 30 Hz, damping 0.8
    p[pl.SP_WN] = 2.0 * math.pi * 30.0
    p[pl.SP_ZETA] = 0.8
    p[pl.SP_TSOL] = 0.005
    p[pl.STROKE_S] = 5e-3
    p[pl.NOTCH_S] = 0.5
    area = edge_area(20.0, 10.0, 0.65, 870.0)  # 20 L/min at 10 bar at full stroke
    for k in (pl.K_FULL_PA, pl.K_FULL_PB, pl.K_FULL_AT, pl.K_FULL_BT):
        p[k] = area
    p[pl.CD] = 0.65
    p[pl.LAM_CRIT] = 100.0
    p[pl.DP_REG] = 0.2 * BAR
    p[pl.CLEAR_G] = math.pi * 0.016 * (2e-6) ** 3 / 12.0  # 16 mm spool, 2 um clearance
    p[pl.CLEAR_L0] = 1e-3


def _pump(p: np.ndarray) -> None:
    # pump: 11 cm^3/rev, compensator 190-200 bar through its own spool and servo piston
    p[pl.D_MAX] = 11e-6 / (2.0 * math.pi)
    p[pl.PC_START], p[pl.PC_FULL] = 190.0 * BAR, 200.0 * BAR
    p[pl.PC_WN] = 2.0 * math.pi * 200.0
    p[pl.PC_LEAD] = 0.005
    p[pl.PC_ZETA] = 0.7
    p[pl.SV_TAU] = 0.02
    p[pl.SV_RATE] = 25.0  # full stroke in 40 ms at the fastest
    p[pl.SLIP40] = 0.25 * LPM / (100.0 * BAR)  # a new pump: 0.25 L/min per 100 bar
    p[pl.RELIEF_CRACK], p[pl.RELIEF_FULL] = 210.0 * BAR, 220.0 * BAR
    p[pl.RELIEF_Q] = 40.0 * LPM
    p[pl.V_PUMP] = 0.5e-3


def _cylinder_and_boom(p: np.ndarray) -> None:
    p[pl.A_CAP] = math.pi / 4.0 * 0.063**2
    p[pl.A_ROD] = p[pl.A_CAP] - math.pi / 4.0 * 0.036**2
    p[pl.STROKE] = 0.5
    p[pl.V_DEAD_A] = p[pl.V_DEAD_B] = 0.3e-3
    p[pl.K_LINE] = 30.0 * LPM / math.sqrt(1.0 * BAR)  # hose and fittings: 1 bar at 30 L/min
    p[pl.K_CUSH] = 2.0 * LPM / math.sqrt(30.0 * BAR)  # cushion: 2 L/min at 30 bar
    p[pl.L_CUSH] = 0.02
    # the boom: rod and piston, then the boom through its structure (a 32 Hz first mode)
    p[pl.M1], p[pl.M2] = 60.0, 340.0
    p[pl.K_STRUCT] = 6e7
    p[pl.C_STRUCT] = 5.5e3
    p[pl.C_VISC] = 2000.0
    p[pl.VISC_SHARE] = 0.2
    p[pl.F_GRAV] = 6000.0
    p[pl.FR_STATIC] = 1.5
    p[pl.FR_VS] = 0.015
    p[pl.FR_VREG] = 0.002
    p[pl.K_STOP], p[pl.C_STOP] = 2e8, 1.5e5
    p[pl.AC_K] = 10.0 * LPM / math.sqrt(1.0 * BAR)
    p[pl.AC_CRACK] = 0.2 * BAR
    # return line: a filter (0.6 bar at 20 L/min at 40 degC, laminar) and the hose
    p[pl.FILTER_R40] = 0.6 * BAR / (20.0 * LPM)
    p[pl.RETURN_KT] = 0.3 * BAR / (20.0 * LPM) ** 2
    p[pl.RETURN_TAU] = 0.005
    p[pl.AIR_TAU_D], p[pl.AIR_TAU_R], p[pl.AIR_BUNSEN] = 1.5, 0.2, 0.09
    p[pl.HOSE_TAU], p[pl.HOSE_PUMP_SHARE] = 0.3, 0.5


def _engine_and_oil(p: np.ndarray) -> None:
    # engine: droop governor, 2240 rpm at no load, 2150 rpm at 60 N m; 3 cylinders
    p[pl.J_ENG] = 0.25
    p[pl.W_NOLOAD], p[pl.W_FULLLOAD] = 2240.0 * RPM, 2150.0 * RPM
    p[pl.T_RATED], p[pl.GOV_TAU], p[pl.T_PARASITIC] = 60.0, 0.05, 8.0
    p[pl.ETA_HM], p[pl.RIPPLE] = 0.9, 0.3
    # oil heat balance: 35 kJ/K, a thermostat opening the cooler at 45-50 degC
    p[pl.C_TH], p[pl.HA0], p[pl.HA_COOL], p[pl.T_THERMO] = 35e3, 30.0, 400.0, 45.0
    p[pl.T_AMB] = 20.0


# The tolerances: (name, parameter indices, share of the class's band). Masses, gravity
# load, viscous friction, valve gain, volumes and the like vary by the whole band; the
# pump's displacement and pressure settings, set at the factory, by a quarter of it.
TOLERANCES: tuple[tuple[str, tuple[int, ...], float], ...] = (
    ("mass", (pl.M1, pl.M2), 1.0),
    ("gravity_load", (pl.F_GRAV,), 1.0),
    ("viscous_friction", (pl.C_VISC,), 1.0),
    ("valve_gain", (pl.K_FULL_PA, pl.K_FULL_PB, pl.K_FULL_AT, pl.K_FULL_BT), 1.0),
    ("volumes", (pl.V_DEAD_A, pl.V_DEAD_B, pl.V_PUMP), 1.0),
    ("bulk_modulus", (pl.BETA0,), 1.0),
    ("structure_stiffness", (pl.K_STRUCT,), 1.0),
    ("spool_bandwidth", (pl.SP_WN,), 1.0),
    ("servo_time", (pl.SV_TAU,), 1.0),
    ("line_restriction", (pl.K_LINE,), 1.0),
    ("displacement", (pl.D_MAX,), 0.25),
    ("compensator", (pl.PC_START, pl.PC_FULL), 0.25),
    ("relief", (pl.RELIEF_CRACK, pl.RELIEF_FULL), 0.25),
)


def draw_tolerances(rng: np.random.Generator, band: float) -> dict[str, float]:
    """Each tolerance's factor, uniform within +-band x its share."""
    return {
        name: 1.0 + band * share * float(rng.uniform(-1.0, 1.0)) for name, _, share in TOLERANCES
    }


def apply_tolerances(p: np.ndarray, factors: dict[str, float]) -> np.ndarray:
    q = p.copy()
    for name, idx, _ in TOLERANCES:
        for i in idx:
            q[i] *= factors[name]
    return q


def initial_state(p: np.ndarray, rod_m: float, temp_c: float) -> np.ndarray:
    """A machine at rest: spool centred, the rod held by the cap side, engine at speed."""
    x = np.zeros(24)
    x[3] = 0.05
    x[4] = 1.0
    x[6] = p[pl.PC_FULL] - 1.0 * BAR
    x[7] = pl.gravity_force(p, rod_m) / p[pl.A_CAP]
    x[9] = rod_m
    x[11] = rod_m - p[pl.F_GRAV] / p[pl.K_STRUCT]
    x[13] = p[pl.W_NOLOAD] - 0.1 * (p[pl.W_NOLOAD] - p[pl.W_FULLLOAD])
    x[14] = p[pl.T_PARASITIC]
    x[16] = temp_c
    x[17:20] = 1.0 if p[pl.AIR_EPS] > 0.0 else 0.0
    return x
