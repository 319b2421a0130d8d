"""Effect formulations and their parameter ranges (units, sources), drawn from a seeded rng.

Each entry: effect name -> {formulation name: function(rng, p) that sets parameters in the
plant vector p}.  Ranges:
- entrained_air: free air 0.5-3 % by volume at 1 bar (Gholizadeh 2011 review, typical mobile
  circuits); `isothermal_mixture` (polytropic n = 1, Yu 1994) and `adiabatic_dissolving`
  (n = 1.4, free air dissolving linearly until 30-80 bar, Henry's law).
- oil_viscosity: VG46 (46 cSt at 40 degC, 6.8 cSt at 100 degC).  `walther_all_paths`
  (ASTM D341 Walther law; laminar leakage in pump, piston seal and valve clearances scales with
  1/nu, viscous friction with sqrt(nu)); `andrade_pump_seal` (Andrade/Vogel exponential
  nu = nu40 exp(-0.034 (T-40)), pump and seal leakage only).  Oil warms 25-40 -> 60-80 degC.
- cylinder_friction: Coulomb 300-800 N, static 1.2-1.8 x Coulomb, Stribeck velocity 5-20 mm/s
  (Armstrong-Helouvry 1994).  `stribeck_tanh` and `lugre` (sigma0 1e6-1e7 N/m, sigma1
  1e3-5e3 N s/m; Canudas de Wit 1995).
- spool_dynamics: `second_order` (5-20 Hz, damping 0.5-0.9, mobile valves, Jelali & Kroll),
  `lag_rate_limit` (time constant 15-40 ms, slew 3-8 stroke/s).
- valve_deadband: overlap 5-15 % of stroke; `linear_overlap`, `progressive_notch` (smooth
  metering notch after the overlap).
- pump_control_dynamics: `first_order` (tau 30-120 ms), `second_order` (3-10 Hz, zeta 0.4-0.8).
- hose_compliance: `series_hose_modulus` (hose modulus 0.3-0.8 GPa in series with oil, Merritt),
  `added_capacitance` (1.5-5e-13 m^3/Pa per chamber, 1/2" hoses of a few metres).
- sensor_lag: `first_order` (tau 20-80 ms) and `transport_delay` (30-100 ms) on PP, PA, PB, QP.
- load_variation: `linear_slope` (+-20-50 % of the gravity load across the stroke),
  `boom_angle_cosine` (boom angle 20-50 deg swept 30-60 deg across the stroke).
- sensor_calibration: `gain` (0.85-0.93 or 1.07-1.15) or `offset` (5-15 bar, 1.5-4 L/min, 10-30 mm)
  on one of PP, PA, PB, QP, RodPos.
"""

from __future__ import annotations

import numpy as np

from .plant import BAR, P

SIGNALS = ("PP", "PA", "PB", "QP", "RodPos")
OFFSET_RANGE = {"PP": (5, 15), "PA": (5, 15), "PB": (5, 15), "QP": (1.5, 4), "RodPos": (10, 30)}


def walther_nu_cst(t_c: float) -> float:
    """ASTM D341 Walther: log log (nu + 0.7) = A - B log T, fitted to VG46 (40/100 degC)."""
    t1, t2, n1, n2 = 313.15, 373.15, 46.0, 6.8
    y1, y2 = np.log10(np.log10(n1 + 0.7)), np.log10(np.log10(n2 + 0.7))
    b = (y1 - y2) / (np.log10(t2) - np.log10(t1))
    a = y1 + b * np.log10(t1)
    return float(10 ** (10 ** (a - b * np.log10(t_c + 273.15))) - 0.7)


def _set(p, **kw):
    for k, v in kw.items():
        p[P[k]] = v


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def air_iso(rng, p, temps):
    _set(p, air_mode=1, air_frac=_u(rng, 0.005, 0.03), air_n=1.0)


def air_adiab(rng, p, temps):
    _set(
        p, air_mode=2, air_frac=_u(rng, 0.005, 0.03), air_n=1.4, air_pdiss_Pa=_u(rng, 30, 80) * BAR
    )


def _leaks(rng, p, all_paths):
    # reference leak conductances at 40 degC (m^3/s/Pa): pump 0.5-1.5 L/min at 200 bar,
    # seal 0.1-0.4 L/min at 100 bar, valve 0.05-0.2 L/min at 100 bar
    _set(
        p, leak_pump=_u(rng, 0.5, 1.5) / 60000 / 200e5, leak_seal=_u(rng, 0.1, 0.4) / 60000 / 100e5
    )
    if all_paths:
        _set(p, leak_valve=_u(rng, 0.05, 0.2) / 60000 / 100e5)


def visc_walther(rng, p, temps):
    _leaks(rng, p, True)
    _set(
        p,
        visc_mode=1,
        visc_ratio0=46.0 / walther_nu_cst(temps[0]),
        visc_ratio1=46.0 / walther_nu_cst(temps[1]),
    )


def visc_andrade(rng, p, temps):
    _leaks(rng, p, False)
    _set(
        p,
        visc_mode=2,
        visc_ratio0=float(np.exp(0.034 * (temps[0] - 40))),
        visc_ratio1=float(np.exp(0.034 * (temps[1] - 40))),
    )


def _fric(rng, p, mode):
    fc = _u(rng, 300, 800)
    _set(
        p,
        fric_mode=mode,
        fc_N=fc,
        fs_N=fc * _u(rng, 1.2, 1.8),
        vs_mps=_u(rng, 0.005, 0.02),
        sigma0=_u(rng, 1e6, 1e7),
        sigma1=_u(rng, 1e3, 5e3),
    )


def fric_stribeck(rng, p, temps):
    _fric(rng, p, 1)


def fric_lugre(rng, p, temps):
    _fric(rng, p, 2)


def spool_2nd(rng, p, temps):
    _set(p, spool_mode=1, spool_wn=2 * np.pi * _u(rng, 5, 20), spool_zeta=_u(rng, 0.5, 0.9))


def spool_lag(rng, p, temps):
    _set(p, spool_mode=2, spool_tau=_u(rng, 0.015, 0.04), spool_rate=_u(rng, 3, 8))


def db_linear(rng, p, temps):
    _set(p, db_mode=1, db_overlap=_u(rng, 0.05, 0.15))


def db_notch(rng, p, temps):
    _set(p, db_mode=2, db_overlap=_u(rng, 0.05, 0.15))


def pump_1st(rng, p, temps):
    _set(p, pump_mode=1, pump_tau=_u(rng, 0.03, 0.12))


def pump_2nd(rng, p, temps):
    _set(p, pump_mode=2, pump_wn=2 * np.pi * _u(rng, 3, 10), pump_zeta=_u(rng, 0.4, 0.8))


def hose_series(rng, p, temps):
    _set(p, hose_mode=1, hose_bulk_Pa=_u(rng, 0.3e9, 0.8e9))


def hose_cap(rng, p, temps):
    _set(p, hose_mode=2, hose_c_m3pPa=_u(rng, 1.5e-13, 5e-13))


def load_slope(rng, p, temps):
    _set(p, load_mode=1, load_k=_u(rng, 0.2, 0.5) * rng.choice([-1, 1]))


def load_cos(rng, p, temps):
    _set(
        p,
        load_mode=2,
        load_theta0=np.radians(_u(rng, 20, 50)),
        load_dtheta=np.radians(_u(rng, 30, 60)),
    )


# post-processing effects (sensor_lag, sensor_calibration) are described by dicts
def lag_first(rng, p, temps):
    return {"lag": "first_order", "tau_s": _u(rng, 0.02, 0.08)}


def lag_delay(rng, p, temps):
    return {"lag": "transport_delay", "delay_s": _u(rng, 0.03, 0.1)}


def cal_gain(rng, p, temps):
    sig = str(rng.choice(SIGNALS))
    g = _u(rng, 0.85, 0.93) if rng.random() < 0.5 else _u(rng, 1.07, 1.15)
    return {"signal": sig, "gain": g}


def cal_offset(rng, p, temps):
    sig = str(rng.choice(SIGNALS))
    lo, hi = OFFSET_RANGE[sig]
    return {"signal": sig, "offset": _u(rng, lo, hi) * rng.choice([-1, 1])}


EFFECTS = {
    "entrained_air": {"isothermal_mixture": air_iso, "adiabatic_dissolving": air_adiab},
    "oil_viscosity": {"walther_all_paths": visc_walther, "andrade_pump_seal": visc_andrade},
    "cylinder_friction": {"stribeck_tanh": fric_stribeck, "lugre": fric_lugre},
    "spool_dynamics": {"second_order": spool_2nd, "lag_rate_limit": spool_lag},
    "valve_deadband": {"linear_overlap": db_linear, "progressive_notch": db_notch},
    "pump_control_dynamics": {"first_order": pump_1st, "second_order": pump_2nd},
    "hose_compliance": {"series_hose_modulus": hose_series, "added_capacitance": hose_cap},
    "sensor_lag": {"first_order": lag_first, "transport_delay": lag_delay},
    "load_variation": {"linear_slope": load_slope, "boom_angle_cosine": load_cos},
    "sensor_calibration": {"gain": cal_gain, "offset": cal_offset},
}


def ooc_periodic(rng, p, temps):
    _set(p, ooc_mode=1, ooc_amp=_u(rng, 800, 2000), ooc_freq=_u(rng, 0.3, 2.0))


def ooc_leak(rng, p, temps):
    # A -> tank leak growing with pA^2: 1-3 L/min at 100 bar
    _set(p, ooc_mode=2, ooc_leak=_u(rng, 1, 3) / 60000 / (100e5**2 / 1e7))


def ooc_pump_setting(rng, p, temps):
    _set(p, ooc_comp_shift_Pa=-_u(rng, 25, 45) * BAR)


OUT_OF_CATALOGUE = {
    "periodic_load": (ooc_periodic, "force_periodic"),
    "pressure_squared_leak_A_tank": (ooc_leak, "leakage"),
    "compensator_setting": (ooc_pump_setting, "pump_setting"),
}
