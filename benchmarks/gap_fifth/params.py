"""The fifth plant's machine: named parameters (SI), their nominal values and tolerances.

The kernel takes one float64 vector; its slots are the module constants below (numba reads
module-level ints as compile-time constants). Everything here is the plant's own choice:
a pressure-compensated pump (compensator spool, control piston against a bias spring, a
swashplate with its own mass and damping; the default) or a load-sensing pump with a
margin spool and an integrating swashplate (`pump_pc` 0), a spool with round
metering holes and steady flow forces, a boom pinned on a linkage (the cylinder's lever arm
changes with the boom angle), seal friction with LuGre bristles, an oil whose viscosity
follows Vogel's law and whose bulk modulus rises with pressure and falls with free air.
"""

from __future__ import annotations

import math

import numpy as np

NAMES = (
    # oil
    "rho", "nu40_cst", "vogel_b_k", "vogel_c_k", "beta0_pa", "beta_slope", "air_frac",
    "air_poly_n",
    # engine and governor
    "eng_inertia", "gov_kp", "gov_ki", "eng_tmax",
    # load-sensing pump
    "disp_max_m3", "margin_pa", "margin_band_pa", "margin_tau_s", "swash_tau_s",
    "ls_tau_s", "cutoff_pa", "cutoff_band_pa", "slip_wilson", "wear_leak_k",
    "disp_stop", "relief_crack_pa", "relief_full_pa", "relief_q_m3s",
    # pressure-compensated pump (pump_pc 1): compensator spool, control piston, bias spring
    "pump_pc", "comp_set_pa", "comp_droop_pa", "comp_band_pa", "comp_tau_s",
    "comp_sense_tau_s", "comp_underlap", "ctl_area_m2", "ctl_restrict_in", "ctl_restrict_vent",
    "ctl_cd", "ctl_piston_m2", "ctl_stroke_m", "ctl_dead_m3", "bias_f0_n", "bias_k_n_m",
    "swash_moment_m2", "swash_mass_kg", "swash_c_n_s_m", "stop_tau_s",
    # pump line and tank
    "vol_p_m3", "tank_p0_pa", "tank_k_pa_s2_m6", "tank_tau_s",
    # valve
    "hole_n", "hole_d_m", "overlap_m", "cd_inf", "lambda_c", "clear_leak_m3",
    "sol_tau_s", "spool_wn", "spool_zeta", "spool_vmax", "flow_force_k", "spring_full_n",
    "edge_bt_scale",
    # lines, hoses
    "line_r_lam", "line_r_turb", "hose_c_a", "hose_c_b", "hose_c_p", "hose_creep",
    "hose_tau_s",
    # cylinder and linkage
    "area_a", "area_b", "stroke_m", "dead_a_m3", "dead_b_m3", "link_a_m", "link_b_m",
    "cyl_l0_m", "psi_off_rad", "boom_j", "boom_mgl", "stop_k", "stop_c",
    "bal_f0_n", "bal_gas_m",
    # friction (LuGre bristles, pressure-loaded seals)
    "fric_c_nu", "fric_fc_n", "fric_fs_n", "fric_vs", "fric_sigma0", "fric_sigma1",
    "fric_kp_n_per_bar", "seal_leak_ab",
    # faults outside the catalogue
    "port_leak_a", "rod_force_amp", "rod_force_hz",
)  # fmt: skip
for _i, _n in enumerate(NAMES):
    globals()["P_" + _n.upper()] = _i
N_PARAMS = len(NAMES)

BORE_M, ROD_M = 0.063, 0.036

NOMINAL: dict[str, float] = {
    "rho": 870.0,
    "nu40_cst": 46.0,
    "vogel_b_k": 839.0,  # Vogel through 46 cSt at 40 degC and 6.8 at 100 (C = -95 degC)
    "vogel_c_k": 95.0,
    "beta0_pa": 1.6e9,
    "beta_slope": 7.0,  # tangent bulk modulus rises 7 Pa per Pa
    "air_frac": 0.0005,  # free air at atmospheric pressure, volume share
    "air_poly_n": 1.15,
    "eng_inertia": 0.45,
    "gov_kp": 3.0,  # N m per rad/s
    "gov_ki": 8.0,
    "eng_tmax": 95.0,
    "disp_max_m3": 11.0e-6,
    "margin_pa": 18e5,
    "margin_band_pa": 8e5,
    "margin_tau_s": 0.004,
    "swash_tau_s": 0.08,
    "ls_tau_s": 0.01,
    "cutoff_pa": 195e5,
    "cutoff_band_pa": 4e5,
    "slip_wilson": 0.6,  # L/min per 100 bar at 46 cSt; the Wilson slip scales with 1/mu
    "wear_leak_k": 0.0,
    "disp_stop": 1.0,
    "relief_crack_pa": 210e5,
    "relief_full_pa": 222e5,
    "relief_q_m3s": 30.0 / 60000.0,
    "pump_pc": 1.0,
    "comp_set_pa": 188e5,  # the compensator spool's null at full displacement
    "comp_droop_pa": 12e5,  # the null rises this much from full to zero displacement
    "comp_band_pa": 8e5,  # PP over the null that opens a control edge fully
    "comp_tau_s": 0.001,  # the compensator spool's lag (its end-chamber damping)
    "comp_sense_tau_s": 0.001,  # the spool's sensing passage from the pump line
    "comp_underlap": 0.08,  # both control edges open this share at null: a bleed
    "ctl_area_m2": 0.5e-6,  # each control edge's area at full spool opening
    "ctl_restrict_in": 1.0,  # share of the supply edge's area a restriction passes
    "ctl_restrict_vent": 1.0,  # share of the vent edge's area a restriction passes
    "ctl_cd": 0.65,
    "ctl_piston_m2": math.pi * 0.016**2 / 4,  # 16 mm control piston
    "ctl_stroke_m": 0.014,  # its stroke from full to zero displacement
    "ctl_dead_m3": 8e-6,  # its chamber and the passages at full displacement
    "bias_f0_n": 900.0,  # bias spring at full displacement
    "bias_k_n_m": 30e3,
    "swash_moment_m2": 1e-5,  # the pistons' destroking moment, as N at the piston per Pa
    "swash_mass_kg": 1.5,  # swashplate and control piston, reduced to the piston
    "swash_c_n_s_m": 1500.0,  # the swashplate's bearings and the piston's seal
    "stop_tau_s": 0.05,  # the displacement stop's proportional solenoid
    "vol_p_m3": 0.5e-3,
    "tank_p0_pa": 1.2e5,
    "tank_k_pa_s2_m6": 1.0e12,
    "tank_tau_s": 0.01,
    "hole_n": 4.0,
    "hole_d_m": 1.85e-3,
    "overlap_m": 0.04e-3,
    "cd_inf": 0.64,
    "lambda_c": 60.0,
    "clear_leak_m3": 1.5e-12,  # laminar clearance leak per edge: m^3/s per Pa, times 1/nu[cSt]
    "sol_tau_s": 0.006,
    "spool_wn": 2 * math.pi * 45.0,
    "spool_zeta": 0.8,
    "spool_vmax": 1e9,
    "flow_force_k": 0.43,  # 2 Cd Cv cos(69 deg)
    "spring_full_n": 140.0,
    "edge_bt_scale": 1.0,
    "line_r_lam": 6.0e6,  # Pa per (m^3/s) per cSt: laminar hose drop
    "line_r_turb": 3.0e12,
    "hose_c_a": 0.0,
    "hose_c_b": 0.0,
    "hose_c_p": 0.0,
    "hose_creep": 0.0,
    "hose_tau_s": 0.25,
    "area_a": math.pi * BORE_M**2 / 4,
    "area_b": math.pi * (BORE_M**2 - ROD_M**2) / 4,
    "stroke_m": 0.5,
    "dead_a_m3": 0.3e-3,
    "dead_b_m3": 0.3e-3,
    "link_a_m": 0.8,
    "link_b_m": 0.9,
    "cyl_l0_m": 0.75,
    "psi_off_rad": math.radians(57.0),
    "boom_j": 190.0,
    "boom_mgl": 4450.0,
    "stop_k": 6e7,
    "stop_c": 2.5e4,
    "bal_f0_n": 0.0,  # a gas balancing strut beside the cylinder: its force at full stroke
    "bal_gas_m": 0.8,  # its gas column (m of its stroke)
    "fric_c_nu": 2000.0,  # N s/m at 46 cSt, scaled by (nu/46)^0.3
    "fric_fc_n": 40.0,
    "fric_fs_n": 60.0,
    "fric_vs": 0.01,
    "fric_sigma0": 4e5,
    "fric_sigma1": 600.0,
    "fric_kp_n_per_bar": 0.0,
    "seal_leak_ab": 0.0,
    "port_leak_a": 0.0,
    "rod_force_amp": 0.0,
    "rod_force_hz": 0.0,
}

# Parts a machine may differ in from the nominal one, each by up to the tolerance band.
TOLERANCED = (
    "boom_j", "boom_mgl", "fric_c_nu", "hole_d_m", "dead_a_m3", "dead_b_m3", "vol_p_m3",
    "disp_max_m3", "margin_pa", "swash_tau_s", "spring_full_n", "slip_wilson", "beta0_pa",
    "cd_inf", "sol_tau_s", "tank_p0_pa",
)  # fmt: skip
# The pressure-compensated pump's parts in the load-sensing pump's two slots (same draws).
PC_TOLERANCED = {"margin_pa": "comp_band_pa", "swash_tau_s": "ctl_area_m2"}
SETTING_SHARE = 0.25  # a compensator is set within a quarter of the band of its setting


def vector(values: dict[str, float]) -> np.ndarray:
    """The kernel's parameter vector from named values (every name required)."""
    missing = set(NAMES) - set(values)
    if missing:
        raise KeyError(f"parameters missing: {sorted(missing)}")
    return np.array([float(values[n]) for n in NAMES], dtype=np.float64)


def machine(rng: np.random.Generator, band: float, pump: str = "pc") -> dict[str, float]:
    """A machine whose toleranced parts are each uniformly within +-band of nominal.

    The displacement only goes down (a pump above its rating would read as another machine).
    `pump` "pc": the compensator's spring rate and control edges take the load-sensing
    pump's two slots (margin, servo), then its setting is drawn within a quarter of the band;
    "ls": the load-sensing pump, drawn exactly as before the compensated pump was added.
    """
    values = dict(NOMINAL)
    values["pump_pc"] = 1.0 if pump == "pc" else 0.0
    for name in TOLERANCED:
        factor = 1.0 + band * rng.uniform(-1.0, 1.0)
        if name == "disp_max_m3":
            factor = 1.0 - band * rng.uniform(0.0, 1.0)
        if pump == "pc":
            name = PC_TOLERANCED.get(name, name)
        values[name] = NOMINAL[name] * factor
    if pump == "pc":
        values["comp_set_pa"] *= 1.0 + SETTING_SHARE * band * rng.uniform(-1.0, 1.0)
    return values


def viscosity_cst(temp_c: float | np.ndarray, nu40: float, b_k: float, c_k: float):
    """Vogel's law through nu40 at 40 degC: nu = nu40 exp(b (1/(T + c) - 1/(40 + c)))."""
    return nu40 * np.exp(b_k * (1.0 / (np.asarray(temp_c) + c_k) - 1.0 / (40.0 + c_k)))
