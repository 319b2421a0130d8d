"""The withheld effects (the catalogue's ten names, this plant's own formulations) and the
faults outside the catalogue, each as a change to one machine.

Every draw takes the recording's own generator in a fixed order, so a key entry rebuilds
its recording. `params` are what the key reports (units in the names).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from benchmarks.gap_fifth.cycle import Warmup, draw_warmup
from benchmarks.gap_fifth.sensors import SensorSet

CATALOGUE = (
    "entrained_air", "oil_viscosity", "cylinder_friction", "spool_dynamics", "valve_deadband",
    "pump_control_dynamics", "hose_compliance", "sensor_lag", "load_variation",
    "sensor_calibration",
)  # fmt: skip
# out-of-catalogue fault -> what a simulation engineer should add (term, signal)
OUTSIDE = {
    "worn_pump": ("leakage", "P->tank"),
    "port_relief_leak": ("leakage", "A->tank"),
    "piston_seal_bypass": ("leakage", "A<->B"),
    "silted_return_edge": ("valve_setting", "B->tank"),
    "vibrating_attachment": ("force_periodic", "rod"),
    "displacement_stop": ("pump_setting", "displacement"),
}
CM3_PER_BAR = 1e-6 / 1e5  # m^3/Pa
PC_STROKE_S = 0.06  # supply edge share = this / the drawn full stroke: 0.2-0.5
PC_LS_TAU_TO_VENT = 4.0  # vent edge share = this x the drawn LS line lag: 0.16-0.6


@dataclass(frozen=True)
class Change:
    """What a withheld effect or fault does to one machine."""

    values: dict[str, float]
    sensors: SensorSet
    warm: Warmup
    params: dict


def _air(rng, v, s, w):
    v["air_frac"] = rng.uniform(0.006, 0.03)
    v["air_poly_n"] = rng.uniform(1.0, 1.2)
    return {"air_fraction": v["air_frac"], "polytropic_n": v["air_poly_n"]}, s, w


def _oil(rng, v, s, w):
    v["nu40_cst"] *= rng.uniform(0.3, 0.55)
    v["vogel_b_k"] *= rng.uniform(1.0, 1.15)
    return {"nu40_cst": v["nu40_cst"], "vogel_b_k": v["vogel_b_k"]}, s, w


def _friction(rng, v, s, w):
    fc = rng.uniform(300.0, 700.0)
    v["fric_fc_n"] = fc
    v["fric_fs_n"] = fc * rng.uniform(1.3, 1.8)
    v["fric_vs"] = rng.uniform(0.005, 0.02)
    v["fric_kp_n_per_bar"] = rng.uniform(1.0, 3.0)
    v["fric_sigma0"] = v["fric_fs_n"] / 1.5e-4
    v["fric_sigma1"] = 600.0 * math.sqrt(v["fric_sigma0"] / 4e5)
    keys = ("fric_fc_n", "fric_fs_n", "fric_vs", "fric_kp_n_per_bar")
    names = ("coulomb_n", "static_n", "stribeck_velocity_m_s", "pressure_n_per_bar")
    return {n: v[k] for n, k in zip(names, keys, strict=True)}, s, w


def _spool(rng, v, s, w):
    v["sol_tau_s"] = rng.uniform(0.03, 0.09)
    v["spool_wn"] = 2 * math.pi * rng.uniform(6.0, 14.0)
    v["spool_zeta"] = rng.uniform(0.5, 0.9)
    v["spool_vmax"] = rng.uniform(3.0, 7.0)
    return (
        {
            "pilot_tau_s": v["sol_tau_s"],
            "natural_freq_hz": v["spool_wn"] / (2 * math.pi),
            "damping_ratio": v["spool_zeta"],
            "max_rate_stroke_per_s": v["spool_vmax"],
        },
        s,
        w,
    )


def _deadband(rng, v, s, w):
    v["overlap_m"] = rng.uniform(0.2e-3, 0.5e-3)
    share = v["overlap_m"] / (v["overlap_m"] + v["hole_d_m"])
    return {"overlap_mm": v["overlap_m"] * 1e3, "overlap_pct_of_stroke": 100 * share}, s, w


def _pump_dyn(rng, v, s, w):
    ls_tau, full_stroke = rng.uniform(0.04, 0.15), rng.uniform(0.12, 0.3)
    if v["pump_pc"]:
        # the compensated pump: restrictions in the control piston's port, the vent (on-stroke)
        # narrower than the supply (destroke); the same two draws as the load-sensing pump's
        v["ctl_restrict_in"] = PC_STROKE_S / full_stroke
        v["ctl_restrict_vent"] = PC_LS_TAU_TO_VENT * ls_tau
        return (
            {"supply_edge_share": v["ctl_restrict_in"], "vent_edge_share": v["ctl_restrict_vent"]},
            s,
            w,
        )
    v["ls_tau_s"] = ls_tau
    v["swash_tau_s"] = full_stroke
    return {"ls_line_tau_s": v["ls_tau_s"], "swash_full_stroke_s": v["swash_tau_s"]}, s, w


def _hoses(rng, v, s, w):
    c = rng.uniform(0.03, 0.12) * CM3_PER_BAR
    v["hose_c_a"] = c
    v["hose_c_b"] = c * rng.uniform(0.8, 1.2)
    v["hose_c_p"] = c * rng.uniform(0.4, 0.8)
    v["hose_creep"] = rng.uniform(0.3, 0.8)
    v["hose_tau_s"] = rng.uniform(0.1, 0.4)
    return (
        {
            "a_cm3_per_bar": v["hose_c_a"] / CM3_PER_BAR,
            "b_cm3_per_bar": v["hose_c_b"] / CM3_PER_BAR,
            "p_cm3_per_bar": v["hose_c_p"] / CM3_PER_BAR,
            "creep_share": v["hose_creep"],
            "creep_tau_s": v["hose_tau_s"],
        },
        s,
        w,
    )


def _lag(rng, v, s, w):
    s = replace(
        s,
        gateway_delay_ms=int(rng.integers(20, 61)),
        snubber_hz=rng.uniform(4.0, 12.0),
        snubber_zeta=rng.uniform(0.6, 1.0),
    )
    return (
        {
            "gateway_delay_ms": s.gateway_delay_ms,
            "snubber_hz": s.snubber_hz,
            "snubber_zeta": s.snubber_zeta,
        },
        s,
        w,
    )


def _load(rng, v, s, w):
    v["bal_f0_n"] = rng.uniform(500.0, 1100.0)
    v["bal_gas_m"] = rng.uniform(0.8, 1.2)
    g = v["bal_gas_m"]
    bottom = v["bal_f0_n"] * (g / (g - v["stroke_m"])) ** 1.3
    return (
        {
            "strut_force_top_n": v["bal_f0_n"],
            "strut_force_bottom_n": bottom,
            "strut_gas_m": g,
        },
        s,
        w,
    )


def _sensor(rng, v, s, w, signal: str):
    gain, offset = dict(s.gain), dict(s.offset)
    if signal in ("PP", "PA", "PB"):
        supply = rng.uniform(0.93, 0.97) if rng.uniform() < 0.5 else rng.uniform(1.03, 1.07)
        zero = rng.uniform(-6.0, 6.0)
        gain[signal] = supply
        offset[signal] = (supply - 1.0) * 50.0 + zero
        params = {f"{signal}_gain": gain[signal], f"{signal}_offset_bar": offset[signal]}
    elif signal == "QP":
        gain["QP"] = rng.uniform(0.86, 0.92) if rng.uniform() < 0.5 else rng.uniform(1.08, 1.14)
        params = {"QP_gain": gain["QP"], "QP_offset_lpm": 0.0}
    else:
        gain["RodPos"] = rng.uniform(0.96, 1.04)
        offset["RodPos"] = rng.choice([-1.0, 1.0]) * rng.uniform(12.0, 30.0)
        params = {"RodPos_gain": gain["RodPos"], "RodPos_offset_mm": offset["RodPos"]}
    return {"sensor_calibration": params}, replace(s, gain=gain, offset=offset), w


def _outside(rng, v, s, w, fault: str):
    if fault == "worn_pump":
        v["wear_leak_k"] = rng.uniform(2.5, 4.5)
        w = draw_warmup(rng, warm_up=True)
        return {"leak_lpm_at_100bar": v["wear_leak_k"], "law": "dp^0.7, any oil"}, s, w
    if fault == "port_relief_leak":
        v["port_leak_a"] = rng.uniform(1.5, 3.5)
        return {"leak_lpm_at_100bar": v["port_leak_a"], "law": "dp^0.8, A to tank"}, s, w
    if fault == "piston_seal_bypass":
        v["seal_leak_ab"] = rng.uniform(1.5, 4.0)
        return {"leak_lpm_per_100bar": v["seal_leak_ab"], "law": "laminar, A<->B"}, s, w
    if fault == "silted_return_edge":
        v["edge_bt_scale"] = rng.uniform(0.35, 0.55)
        return {"b_to_tank_area_share": v["edge_bt_scale"]}, s, w
    if fault == "vibrating_attachment":
        v["rod_force_amp"] = rng.uniform(800.0, 1800.0)
        v["rod_force_hz"] = rng.uniform(1.2, 4.5)
        return {"amplitude_n": v["rod_force_amp"], "frequency_hz": v["rod_force_hz"]}, s, w
    v["disp_stop"] = rng.uniform(0.7, 0.85)
    return {"displacement_stop_share": v["disp_stop"]}, s, w


EFFECTS = {
    "entrained_air": _air,
    "oil_viscosity": _oil,
    "cylinder_friction": _friction,
    "spool_dynamics": _spool,
    "valve_deadband": _deadband,
    "pump_control_dynamics": _pump_dyn,
    "hose_compliance": _hoses,
    "sensor_lag": _lag,
    "load_variation": _load,
}


def apply(rng: np.random.Generator, kind: str, name: str, values, sensors, warm, signal=None):
    """The machine with one withheld effect (`effect`), fault (`outside`) or none (`healthy`)."""
    v = dict(values)
    if kind == "healthy":
        return Change(v, sensors, warm, {})
    if kind == "outside":
        params, s, w = _outside(rng, v, sensors, warm, name)
    elif name == "sensor_calibration":
        params, s, w = _sensor(rng, v, sensors, warm, signal)
    else:
        params, s, w = EFFECTS[name](rng, v, sensors, warm)
    return Change(v, s, w, {k: _plain(x) for k, x in params.items()})


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(y) for k, y in x.items()}
    if isinstance(x, (float, np.floating)):
        return round(float(x), 6)
    if isinstance(x, np.integer):
        return int(x)
    return x
