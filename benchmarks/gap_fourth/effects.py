"""The withheld effects, in this plant's own formulations: each draws its parameters (in a
user's units, stored in the key) and applies them to the parameter vector or the sensors.

Out-of-catalogue faults carry the mechanism `monitor gap` should put first in its
`suggestion` (term and signal, in the docs' vocabulary)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.gap_fourth import params as pr
from benchmarks.gap_fourth import plant as pl

CATALOGUE = (
    "cylinder_friction",
    "sensor_lag",
    "oil_viscosity",
    "entrained_air",
    "hose_compliance",
    "valve_deadband",
    "spool_dynamics",
    "pump_control_dynamics",
    "load_variation",
    "sensor_calibration",
)
OUTSIDE = {
    "worn_pump": ("leakage", "P->tank"),
    "piston_seal_bypass": ("leakage", "A<->B"),
    "port_relief_leak": ("leakage", "A->tank"),
    "compensator_low": ("pump_setting", "compensator"),
    "travel_vibration": ("force_periodic", "rod"),
    "chip_in_notch": ("valve_setting", "P->A"),
}


def _u(rng: np.random.Generator, lo: float, hi: float, nd: int = 4) -> float:
    return round(float(rng.uniform(lo, hi)), nd)


def _friction(rng):
    f100 = _u(rng, 450.0, 900.0, 1)
    return {
        "coulomb_at_100bar_n": f100,
        "zero_pressure_share": _u(rng, 0.35, 0.6, 3),
        "breakaway_ratio": _u(rng, 1.3, 1.8, 3),
        "stribeck_mm_s": _u(rng, 5.0, 20.0, 2),
    }


def _friction_apply(p, s, k):
    f0 = k["coulomb_at_100bar_n"] * k["zero_pressure_share"]
    p[pl.FR_C0] = f0
    p[pl.FR_KP] = (k["coulomb_at_100bar_n"] - f0) / (100.0 * pr.BAR)
    p[pl.FR_STATIC] = k["breakaway_ratio"]
    p[pl.FR_VS] = k["stribeck_mm_s"] / 1000.0


def _lag(rng):
    return {"gateway_delay_ms": int(rng.integers(20, 46)), "snubber_ms_at_40c": _u(rng, 8, 25, 2)}


def _lag_apply(p, s, k):
    s["delay_ms"] = k["gateway_delay_ms"]
    s["snubber_ms"] = k["snubber_ms_at_40c"]


def _oil(rng):
    return {"nu40_cst": _u(rng, 8.0, 14.0, 2)}


def _oil_apply(p, s, k):
    # the same viscosity-temperature slope as the VG46, a thinner grade
    y40 = math.log10(math.log10(k["nu40_cst"] + 0.7))
    p[pl.WAL_A] = y40 + p[pl.WAL_B] * math.log10(313.15)


def _air(rng):
    return {"air_share_at_1atm": _u(rng, 0.005, 0.03, 4), "dissolve_s": _u(rng, 1.0, 4.0, 2)}


def _air_apply(p, s, k):
    p[pl.AIR_EPS] = k["air_share_at_1atm"]
    p[pl.AIR_TAU_D] = k["dissolve_s"]


def _hose(rng):
    return {
        "hose_cm3_per_bar": _u(rng, 0.08, 0.25, 4),
        "instant_share": _u(rng, 0.5, 0.7, 3),
        "creep_s": _u(rng, 0.2, 0.6, 3),
    }


def _hose_apply(p, s, k):
    c = k["hose_cm3_per_bar"] * 1e-6 / pr.BAR
    p[pl.HOSE_CF] = c * k["instant_share"]
    p[pl.HOSE_CS] = c * (1.0 - k["instant_share"])
    p[pl.HOSE_TAU] = k["creep_s"]


def _deadband(rng):
    return {"overlap_pct": _u(rng, 6.0, 16.0, 2)}


def _deadband_apply(p, s, k):
    p[pl.LAP] = k["overlap_pct"] / 100.0 * p[pl.STROKE_S]


def _spool(rng):
    return {"full_stroke_ms": _u(rng, 125.0, 250.0, 1), "pilot_ms": _u(rng, 25.0, 60.0, 1)}


def _spool_apply(p, s, k):
    p[pl.SP_SLOW_TAU] = k["pilot_ms"] / 1000.0
    p[pl.SP_SLOW_VMAX] = 1000.0 / k["full_stroke_ms"]


def _pumpdyn(rng):
    return {"servo_ms": _u(rng, 60.0, 150.0, 1), "full_stroke_ms": _u(rng, 125.0, 330.0, 1)}


def _pumpdyn_apply(p, s, k):
    p[pl.SV_TAU] = k["servo_ms"] / 1000.0
    p[pl.SV_RATE] = 1000.0 / k["full_stroke_ms"]


def _load(rng):
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    return {
        "boom_angle_mid_rad": round(sign * float(rng.uniform(0.25, 0.5)), 4),
        "angle_span_rad": _u(rng, 0.9, 1.3, 4),
    }


def _load_apply(p, s, k):
    p[pl.LOAD_THETA0] = k["boom_angle_mid_rad"]
    p[pl.LOAD_SPAN] = k["angle_span_rad"]


def load_change_n(k: dict, f_grav: float = 6000.0) -> float:
    """The pose effect's load change from the bottom to the top of the stroke (N)."""
    th, sp = k["boom_angle_mid_rad"], k["angle_span_rad"]
    return f_grav * (math.cos(th + sp / 2) - math.cos(th - sp / 2)) / math.cos(th)


def _cal(rng, signal):
    if signal in ("PP", "PA", "PB"):
        if rng.uniform() < 0.5:  # a 350 bar transmitter set up as 400, or the reverse
            gain = 400.0 / 350.0 if rng.uniform() < 0.5 else 350.0 / 400.0
            offset = _u(rng, -3.0, 3.0, 2)
        else:  # a zero that drifted
            gain = _u(rng, 0.96, 1.04, 4)
            offset = round(float(rng.choice([-1.0, 1.0]) * rng.uniform(5.0, 12.0)), 2)
    elif signal == "QP":
        gain = round(float(rng.choice([-1.0, 1.0]) * rng.uniform(0.06, 0.12)) + 1.0, 4)
        offset = _u(rng, -1.5, 1.5, 2)
    else:
        gain = _u(rng, 0.95, 1.05, 4)
        offset = round(float(rng.choice([-1.0, 1.0]) * rng.uniform(10.0, 35.0)), 2)
    return {"signal": signal, "gain": round(gain, 5), "offset": offset}


def _cal_apply(p, s, k):
    s["cal_signal"], s["cal_gain"], s["cal_offset"] = k["signal"], k["gain"], k["offset"]


def _worn(rng):
    return {"leak_lpm_at_200bar": _u(rng, 3.0, 6.0, 3)}


def _worn_apply(p, s, k):
    p[pl.WORN_K] = k["leak_lpm_at_200bar"] * pr.LPM / math.sqrt(200.0 * pr.BAR)


def _bypass(rng):
    return {"leak_lpm_at_100bar": _u(rng, 1.5, 4.0, 3)}


def _bypass_apply(p, s, k):
    p[pl.LEAK_AB_K] = k["leak_lpm_at_100bar"] * pr.LPM / math.sqrt(100.0 * pr.BAR)


def _relief_leak(rng):
    return {"leak_lpm_at_100bar": _u(rng, 1.0, 3.0, 3)}


def _relief_leak_apply(p, s, k):
    p[pl.LEAK_AT_K] = k["leak_lpm_at_100bar"] * pr.LPM / math.sqrt(100.0 * pr.BAR)


def _comp(rng):
    return {"shift_bar": -_u(rng, 25.0, 45.0, 2)}


def _comp_apply(p, s, k):
    p[pl.PC_START] += k["shift_bar"] * pr.BAR
    p[pl.PC_FULL] += k["shift_bar"] * pr.BAR


def _vib(rng):
    return {
        "amplitude_n": _u(rng, 400.0, 900.0, 1),
        "frequency_hz": _u(rng, 1.2, 3.0, 3),
        "phase_rad": _u(rng, 0.0, 6.283, 3),
    }


def _vib_apply(p, s, k):
    p[pl.F_PER_AMP] = k["amplitude_n"]
    p[pl.F_PER_HZ] = k["frequency_hz"]
    p[pl.F_PER_PHASE] = k["phase_rad"]


def _chip(rng):
    return {"blocked_share": _u(rng, 0.3, 0.5, 3)}


def _chip_apply(p, s, k):
    p[pl.B_NOTCH_BLOCK] = k["blocked_share"]


Effect = tuple[Callable[..., dict[str, Any]], Callable[..., None]]
EFFECTS: dict[str, Effect] = {
    "none": (lambda rng: {}, lambda p, s, k: None),
    "cylinder_friction": (_friction, _friction_apply),
    "sensor_lag": (_lag, _lag_apply),
    "oil_viscosity": (_oil, _oil_apply),
    "entrained_air": (_air, _air_apply),
    "hose_compliance": (_hose, _hose_apply),
    "valve_deadband": (_deadband, _deadband_apply),
    "spool_dynamics": (_spool, _spool_apply),
    "pump_control_dynamics": (_pumpdyn, _pumpdyn_apply),
    "load_variation": (_load, _load_apply),
    "sensor_calibration": (_cal, _cal_apply),
    "worn_pump": (_worn, _worn_apply),
    "piston_seal_bypass": (_bypass, _bypass_apply),
    "port_relief_leak": (_relief_leak, _relief_leak_apply),
    "compensator_low": (_comp, _comp_apply),
    "travel_vibration": (_vib, _vib_apply),
    "chip_in_notch": (_chip, _chip_apply),
}


def sensor_defaults() -> dict[str, Any]:
    return {
        "delay_ms": 0,
        "snubber_ms": 0.0,
        "cal_signal": None,
        "cal_gain": 1.0,
        "cal_offset": 0.0,
    }


def apply(effect: str, k: dict, p: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    q = p.copy()
    s = sensor_defaults()
    EFFECTS[effect][1](q, s, k)
    return q, s
