"""Nominal parameters (the reference machine of docs/reference/contracts.md), tolerance
draws, and the withheld effects with their answer keys."""

from __future__ import annotations

import numpy as np

from benchmarks.gap_third import plant
from benchmarks.gap_third.plant import BAR, IX

LPM = 1.0 / 60000.0  # m^3/s per L/min
CM3_PER_BAR = 1e-6 / BAR  # m^3/Pa

# Parameters a machine's tolerance moves (each drawn on its own); pressure settings move a
# quarter as much (valves are set to within a few bar).
TOLERANCED = (
    "inertia",
    "grav_moment",
    "c_visc",
    "kv_pa",
    "kv_at",
    "kv_pb",
    "kv_bt",
    "v0a",
    "v0b",
    "v_line",
    "beta0",
    "d_max",
    "tau_cp",
    "wn_spool",
    "pump_slip40",
    "dpt0",
    "eta_m",
    "flow_force",
    "hose_cap",
)
SETTINGS = ("p_comp_start", "p_comp_full", "p_relief_crack", "p_relief_full")

CATALOGUE = (
    "entrained_air",
    "oil_viscosity",
    "cylinder_friction",
    "spool_dynamics",
    "valve_deadband",
    "pump_control_dynamics",
    "hose_compliance",
    "sensor_lag",
    "load_variation",
    "sensor_calibration",
)
# out-of-catalogue effects and the mechanism (suggestion kind) a diagnosis should name first
OUT_OF_CATALOGUE = {
    "worn_pump": "leakage",
    "check_valve_leak": "leakage",
    "compensator_low": "pump_setting",
    "relief_low": "pump_setting",
    "periodic_force": "force_periodic",
    "scored_rod": "force_velocity",
}


def nominal() -> np.ndarray:
    """The reference machine's values in this plant's formulation (SI)."""
    v = dict(
        rho=870.0,
        beta0=1.5e9,
        beta_slope=8.0,
        nu40=46e-6,
        d_max=11e-6,
        tau_cp=0.012,
        rate_cp=30.0,
        p_comp_start=190 * BAR,
        p_comp_full=200 * BAR,
        p_relief_crack=210 * BAR,
        p_relief_full=220 * BAR,
        v_line=0.5e-3,
        notch=0.15,
        overlap=0.0,
        dpt0=0.3 * BAR,
        k_clear=0.005 * LPM / (100 * BAR),
        wn_spool=2 * np.pi * 60,
        zeta_spool=0.8,
        rate_spool=40.0,
        flow_force=0.02,
        area_a=np.pi / 4 * 0.063**2,
        stroke=0.5,
        v0a=0.3e-3,
        v0b=0.3e-3,
        c_visc=2000.0,
        visc_p_share=0.2,
        arm_a=0.9,
        arm_r=0.5,
        len0=0.54,
        tilt=np.radians(1.0),
        stick_moment=0.0,
        stick_angle=0.0,
        fc=0.0,
        fs=0.0,
        vs=0.01,
        sigma0=0.0,
        sigma1=0.0,
        pump_slip40=0.1 * LPM / (100 * BAR),
        slip_visc_exp=1.0,
        c_int=0.0,
        c_check=0.0,
        air=0.0,
        hose_cap=0.004 * CM3_PER_BAR,
        hose_p=50 * BAR,
        tau_engine=0.3,
        droop=1.0,
        eta_m=0.9,
        pt0=0.5 * BAR,
        kt=4.5e11,
        f_per=0.0,
        w_per=0.0,
        k_stop=5e7,
        c_stop=2e5,
        visc_fric_exp=0.2,
    )
    kv = 20 * LPM / np.sqrt(10 * BAR)
    v.update(kv_pa=kv, kv_at=kv, kv_pb=kv, kv_bt=kv, area_b=np.pi / 4 * (0.063**2 - 0.036**2))
    v["q_max"] = v["d_max"] * 2200 / 60
    prm = np.zeros(len(plant.NAMES))
    for k, val in v.items():
        prm[IX[k]] = val
    _set_geometry(prm)
    return prm


def _set_geometry(prm: np.ndarray) -> None:
    """Boom pose at mid stroke horizontal (+tilt); 400 kg and 6 kN at the rod there."""
    a, r, length = prm[IX["arm_a"]], prm[IX["arm_r"]], prm[IX["len0"]] + 0.25
    prm[IX["phi_mid"]] = np.arccos((a * a + r * r - length * length) / (2 * a * r))
    h, theta = plant.boom_geometry(prm, 0.25)
    prm[IX["inertia"]] = 400.0 * h * h
    prm[IX["grav_moment"]] = 6000.0 * h / np.cos(theta)


def draw_machine(prm: np.ndarray, tol: float, rng: np.random.Generator) -> dict:
    """Move each toleranced parameter by U(-tol, tol) (settings by a quarter); the factors."""
    factors = {}
    for name in TOLERANCED:
        f = 1.0 + rng.uniform(-tol, tol)
        prm[IX[name]] *= f
        factors[name] = round(f, 4)
    shift = rng.uniform(-tol, tol) / 4
    for name in SETTINGS:  # compensator and relief set together, a few bar off
        prm[IX[name]] *= 1.0 + shift
        factors[name] = round(1.0 + shift, 4)
    prm[IX["q_max"]] = prm[IX["d_max"]] * 2200 / 60
    return factors


def slope_n_per_mm(prm: np.ndarray, dx: float = 0.05) -> float:
    """Load change per mm of stroke around mid stroke (N/mm), for the answer key."""
    return (plant.load_force(prm, 0.25 + dx) - plant.load_force(prm, 0.25 - dx)) / (2e3 * dx)


def apply_effect(
    name: str, prm: np.ndarray, rng: np.random.Generator, rodpos: bool
) -> tuple[dict, dict]:
    """Set one effect in `prm`; returns (answer-key params, sensor settings)."""
    u = rng.uniform
    sens: dict = {}
    if name == "entrained_air":
        prm[IX["air"]] = u(0.004, 0.02)
        return {"air_fraction_at_atm": prm[IX["air"]], "law": "isothermal"}, sens
    if name in ("oil_viscosity", "worn_pump"):
        leak = u(1.5, 3.0) if name == "oil_viscosity" else u(2.0, 4.0)
        prm[IX["pump_slip40"]] = leak * LPM / (100 * BAR)
        prm[IX["slip_visc_exp"]] = 1.0 if name == "oil_viscosity" else 0.0
        key = {
            "pump_leak_lpm_per_100bar_at_40c": leak,
            "follows_viscosity": name == "oil_viscosity",
        }
        if name == "oil_viscosity":
            prm[IX["visc_fric_exp"]] = u(0.5, 1.0)
            key["friction_viscosity_exponent"] = prm[IX["visc_fric_exp"]]
        return key, sens
    if name == "cylinder_friction":
        fc = u(400, 900)
        m = prm[IX["inertia"]] / 0.5**2
        sigma0 = u(1e6, 4e6)
        vals = dict(
            fc=fc,
            fs=fc * u(1.3, 1.8),
            vs=u(0.005, 0.02),
            sigma0=sigma0,
            sigma1=2 * 0.4 * np.sqrt(sigma0 * m),
        )
        for k, val in vals.items():
            prm[IX[k]] = val
        return {
            "law": "lugre",
            "coulomb_n": fc,
            "static_n": vals["fs"],
            "stribeck_velocity_mm_s": vals["vs"] * 1e3,
            "sigma0_n_per_m": sigma0,
        }, sens
    if name == "spool_dynamics":
        f, z, rate = u(3, 8), u(0.5, 1.0), u(3, 8)
        prm[IX["wn_spool"]], prm[IX["zeta_spool"]], prm[IX["rate_spool"]] = 2 * np.pi * f, z, rate
        return {"natural_freq_hz": f, "damping_ratio": z, "rate_limit_stroke_per_s": rate}, sens
    if name == "valve_deadband":
        prm[IX["overlap"]] = u(0.06, 0.2)
        return {"overlap_pct": 100 * prm[IX["overlap"]]}, sens
    if name == "pump_control_dynamics":
        prm[IX["tau_cp"]], prm[IX["rate_cp"]] = u(0.06, 0.25), u(2, 6)
        return {
            "time_constant_ms": 1e3 * prm[IX["tau_cp"]],
            "slew_limit_per_s": prm[IX["rate_cp"]],
        }, sens
    if name == "hose_compliance":
        cap, p_h = u(0.05, 0.3), u(50, 150)
        prm[IX["hose_cap"]], prm[IX["hose_p"]] = cap * CM3_PER_BAR, p_h * BAR
        return {"hose_capacitance_cm3_per_bar_at_0bar": cap, "stiffening_bar": p_h}, sens
    if name == "sensor_lag":
        sens = {
            "delay_ms": u(15, 60),
            "time_constant_ms": u(0, 30),
            "update_ms": float(rng.choice([1, 10, 20])),
            "signals": ["PP", "PA", "PB", "QP"],
        }
        return dict(sens), sens
    if name == "load_variation":
        prm[IX["stick_moment"]] = u(1500, 3500)
        prm[IX["stick_angle"]] = np.radians(u(40, 70)) * rng.choice([-1, 1])
        return {
            "stick_moment_nm": prm[IX["stick_moment"]],
            "stick_angle_deg": np.degrees(prm[IX["stick_angle"]]),
            "slope_n_per_mm": slope_n_per_mm(prm),
        }, sens
    if name == "sensor_calibration":
        return _calibration(rng, rodpos)
    return _out_of_catalogue(name, prm, rng), sens


def _calibration(rng: np.random.Generator, rodpos: bool) -> tuple[dict, dict]:
    signal = str(rng.choice(["PP", "PA", "PB", "QP"] + (["RodPos"] if rodpos else [])))
    span = {"PP": (3, 10), "PA": (3, 10), "PB": (3, 10), "QP": (1, 3), "RodPos": (10, 30)}
    form = rng.choice(["gain", "offset", "both"])
    gain = rng.uniform(1.05, 1.15) ** rng.choice([-1, 1]) if form != "offset" else 1.0
    offset = rng.uniform(*span[signal]) * rng.choice([-1, 1]) if form != "gain" else 0.0
    sens = {"signal": signal, "gain": gain, "offset": offset}
    return dict(sens), sens


def _out_of_catalogue(name: str, prm: np.ndarray, rng: np.random.Generator) -> dict:
    u = rng.uniform
    if name == "check_valve_leak":  # load-holding check seeping from A to tank
        leak = u(0.5, 1.5)
        prm[IX["c_check"]] = leak * LPM / (100 * BAR)
        return {"leak_lpm_per_100bar": leak, "path": "A->tank"}
    if name == "compensator_low":
        shift = u(25, 40)
        prm[IX["p_comp_start"]] -= shift * BAR
        prm[IX["p_comp_full"]] -= shift * BAR
        return {"shift_bar": -shift}
    if name == "relief_low":
        crack = u(150, 170)
        prm[IX["p_relief_crack"]], prm[IX["p_relief_full"]] = crack * BAR, (crack + 10) * BAR
        return {"relief_crack_bar": crack}
    if name == "periodic_force":
        amp, f = u(300, 800), u(0.8, 3.0)
        prm[IX["f_per"]], prm[IX["w_per"]] = amp, 2 * np.pi * f
        return {"amplitude_n": amp, "frequency_hz": f}
    if name == "scored_rod":
        k = u(2.5, 4.0)
        prm[IX["c_visc"]] *= k
        return {"viscous_friction_factor": k}
    raise ValueError(f"unknown effect {name!r}")
