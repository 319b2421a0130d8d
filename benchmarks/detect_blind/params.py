"""Parameters of the outsider's boom loop: the nominal machine and machines drawn around it.

SI units throughout (m, s, Pa, kg, m^3/s). The nominal is the reference machine of the
contracts (1.7 t mini excavator boom: 11 cm^3/rev pump at 2200 rpm, compensator 190-200 bar,
relief 210 bar, 20 L/min per metering edge at 10 bar, 63/36 mm x 500 mm cylinder, 400 kg at
the rod, 6 kN gravity load); the formulations of every part are this benchmark's own.
"""

from __future__ import annotations

import numpy as np

BAR = 1e5
LPM = 1e-3 / 60.0

# Index of each parameter in the vector the kernel reads.
NAMES = (
    "pump_disp_m3",  # max displacement per revolution
    "pump_tau_s",  # swash (displacement control) time constant
    "comp_crack_pa",  # compensator starts destroking
    "comp_full_pa",  # compensator fully destroked
    "pump_leak_m3_spa",  # laminar pump case leakage at the reference viscosity
    "pump_ripple",  # flow ripple amplitude (share of the geometric flow), 9 pistons
    "relief_crack_pa",
    "relief_full_pa",  # relief passes the rated pump flow here
    "line_volume_m3",  # pump to valve
    "line_beta_pa",  # effective bulk modulus of the pump line (oil and hose)
    "oil_beta_pa",  # pure oil bulk modulus
    "air_fraction",  # free air at atmospheric pressure (share of volume)
    "rho_kg_m3",
    "nu40_cst",  # viscosity at 40 degC (Walther line through nu100)
    "nu100_cst",
    "kv_full",  # metering edge coefficient at full stroke, m^3/s per sqrt(Pa)
    "dp_lam_pa",  # laminar-turbulent transition pressure drop at 40 degC
    "overlap_p",  # P-edge overlap (share of stroke)
    "overlap_t",  # tank-edge overlap
    "area_exp",  # opening = ((|u| - overlap) / (1 - overlap)) ** area_exp
    "valve_leak_m3_spa",  # radial clearance leakage across a closed land at 40 degC
    "spool_wn_rad_s",  # spool natural frequency
    "spool_zeta",
    "tank_pa",  # return line back pressure
    "bore_m",
    "rod_m",
    "stroke_m",
    "dead_volume_m3",  # each side, hoses included
    "mass_kg",
    "gravity_n",  # gravity load against extension at mid-stroke, empty bucket
    "visc_friction_ns_m",  # at 40 degC
    "coulomb_n",
    "stribeck_ratio",  # static / Coulomb friction
    "stribeck_v_m_s",
    "seal_drag",  # extra Coulomb friction per newton of pressure force
    "stop_k_n_m",
    "stop_c_ns_m",
)
IDX = {name: i for i, name in enumerate(NAMES)}

NOMINAL = {
    "pump_disp_m3": 11e-6,
    "pump_tau_s": 0.004,
    "comp_crack_pa": 190 * BAR,
    "comp_full_pa": 200 * BAR,
    "pump_leak_m3_spa": 0.6 * LPM / (200 * BAR),
    "pump_ripple": 0.01,
    "relief_crack_pa": 210 * BAR,
    "relief_full_pa": 220 * BAR,
    "line_volume_m3": 0.5e-3,
    "line_beta_pa": 0.8e9,
    "oil_beta_pa": 1.5e9,
    "air_fraction": 0.004,
    "rho_kg_m3": 870.0,
    "nu40_cst": 46.0,
    "nu100_cst": 6.8,
    "kv_full": 20 * LPM / np.sqrt(10 * BAR),
    "dp_lam_pa": 1.5 * BAR,
    "overlap_p": 0.06,
    "overlap_t": 0.04,
    "area_exp": 1.4,
    "valve_leak_m3_spa": 0.02 * LPM / (100 * BAR),
    "spool_wn_rad_s": 2 * np.pi * 12.0,
    "spool_zeta": 0.7,
    "tank_pa": 1.0 * BAR,
    "bore_m": 0.063,
    "rod_m": 0.036,
    "stroke_m": 0.5,
    "dead_volume_m3": 0.3e-3,
    "mass_kg": 400.0,
    "gravity_n": 6000.0,
    "visc_friction_ns_m": 2000.0,
    "coulomb_n": 150.0,
    "stribeck_ratio": 1.6,
    "stribeck_v_m_s": 0.01,
    "seal_drag": 0.01,
    "stop_k_n_m": 2e7,
    "stop_c_ns_m": 1e5,
}

# Held fixed between machines: geometry that a drawing fixes, and numerical parameters.
FIXED = frozenset({"stroke_m", "stop_k_n_m", "stop_c_ns_m", "rho_kg_m3", "spool_zeta"})


def nominal() -> np.ndarray:
    """The nominal parameter vector."""
    return np.array([NOMINAL[n] for n in NAMES], dtype=np.float64)


def draw_machine(rng: np.random.Generator, tolerance: float) -> np.ndarray:
    """A machine whose every parameter is drawn independently within +-tolerance (uniform).

    Pairs that must stay ordered (compensator crack < full, relief crack < full, rod < bore,
    compensator below relief) are drawn as the first value and a drawn span.
    """
    p = nominal()
    for i, name in enumerate(NAMES):
        if name not in FIXED:
            p[i] *= 1.0 + rng.uniform(-tolerance, tolerance)
    for lo, hi in (("comp_crack_pa", "comp_full_pa"), ("relief_crack_pa", "relief_full_pa")):
        span = (NOMINAL[hi] - NOMINAL[lo]) * (1.0 + rng.uniform(-tolerance, tolerance))
        p[IDX[hi]] = p[IDX[lo]] + span
    p[IDX["relief_crack_pa"]] = max(p[IDX["relief_crack_pa"]], p[IDX["comp_full_pa"]] + 3 * BAR)
    p[IDX["relief_full_pa"]] = max(p[IDX["relief_full_pa"]], p[IDX["relief_crack_pa"]] + 5 * BAR)
    p[IDX["nu100_cst"]] = min(p[IDX["nu100_cst"]], 0.5 * p[IDX["nu40_cst"]])
    return p


def walther(nu40_cst: float, nu100_cst: float) -> tuple[float, float]:
    """Walther (ASTM D341) constants (A, B): log10(log10(nu + 0.7)) = A - B log10(T_K)."""
    w40 = np.log10(np.log10(nu40_cst + 0.7))
    w100 = np.log10(np.log10(nu100_cst + 0.7))
    b = (w40 - w100) / (np.log10(373.15) - np.log10(313.15))
    return float(w40 + b * np.log10(313.15)), float(b)


def viscosity_cst(temp_c: np.ndarray | float, nu40_cst: float, nu100_cst: float):
    """Kinematic viscosity in cSt at temp_c from the Walther line."""
    a, b = walther(nu40_cst, nu100_cst)
    return 10.0 ** (10.0 ** (a - b * np.log10(np.asarray(temp_c) + 273.15))) - 0.7
