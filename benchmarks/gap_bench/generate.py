"""Recordings with a hidden effect (or none, two, or a disturbance outside the catalogue).

Every case is another machine of the type: mass, gravity load, viscous friction, valve
gain and each volume drawn within +-5 % of nominal, sensor noise as on the reference
machine.  Half of the effect cases come from ``monitor.sim`` with its catalogue
formulations, half from the independent plant in ``plant.py`` with other formulations.
Labels go to a separate file; the recordings carry nothing but the contract columns.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
from plant import (
    AIR,
    AIRN,
    EWALL,
    FC,
    FS,
    K1,
    K2,
    KRET,
    KV,
    LEAK,
    LUGRE,
    OVL,
    PAMP,
    PFREQ,
    PRATE,
    PTAU,
    SIG0,
    SIG1,
    SPOOL,
    SVMAX,
    VS,
    WN,
    XLEAK,
    ZETA,
    nominal,
    run,
    sensors,
)

from monitor.io.csvio import write_csv
from monitor.io.recording import Recording
from monitor.signals import COMMAND_NAMES
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

TOLERANCE = 0.05
EFFECTS = (
    "entrained_air",
    "oil_viscosity",
    "cylinder_friction",
    "spool_dynamics",
    "valve_deadband",
    "pump_control_dynamics",
    "hose_compliance",
    "sensor_lag",
    "load_variation",
)
DISTURBANCES = ("periodic_load", "blocked_return", "cross_port_leak")
#: Pairs whose second effect is large enough to matter next to the first.
PAIRS = (
    ("valve_deadband", "sensor_lag"),
    ("cylinder_friction", "load_variation"),
    ("entrained_air", "pump_control_dynamics"),
)


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


# --- catalogue formulations (monitor.sim), parameters in the plausible range -------------
def catalogue_params(name: str, rng: np.random.Generator) -> dict[str, float]:
    if name == "entrained_air":
        return {"air_fraction": float(np.exp(rng.uniform(np.log(0.005), np.log(0.05))))}
    if name == "oil_viscosity":
        return {"pump_leak_lpm_per_100bar": _u(rng, 1.5, 4.0), "friction_share": _u(rng, 0.3, 1)}
    if name == "cylinder_friction":
        c = _u(rng, 500, 2000)
        return {
            "coulomb_n": c,
            "static_n": c * _u(rng, 1.2, 2.0),
            "stribeck_velocity_mm_s": _u(rng, 5, 20),
        }
    if name == "spool_dynamics":
        return {"natural_freq_hz": _u(rng, 3, 12), "damping_ratio": _u(rng, 0.5, 1.0)}
    if name == "valve_deadband":
        return {"overlap_pct": _u(rng, 5, 20)}
    if name == "pump_control_dynamics":
        return {"time_constant_ms": _u(rng, 50, 300)}
    if name == "hose_compliance":
        return {"wall_modulus_gpa": _u(rng, 0.2, 1.0)}
    if name == "sensor_lag":
        return {"delay_ms": _u(rng, 10, 60), "time_constant_ms": _u(rng, 0, 30)}
    if name == "load_variation":
        return {"slope_n_per_mm": float(rng.choice([-1, 1]) * _u(rng, 5, 15))}
    raise ValueError(name)


# --- alternative formulations (plant.py) -----------------------------------------------
def alternative(name: str, q: np.ndarray, rng: np.random.Generator) -> tuple[dict, dict]:
    """Switch ``name`` on in the plant vector ``q``; returns (params, sensor options)."""
    p: dict[str, float] = {}
    sens: dict[str, float] = {}
    if name == "entrained_air":
        q[AIR] = p["air_fraction"] = float(np.exp(rng.uniform(np.log(0.005), np.log(0.05))))
        q[AIRN] = p["polytropic_index"] = _u(rng, 1.0, 1.4)
    elif name == "oil_viscosity":
        q[LEAK] = _u(rng, 1.5, 4.0) / 60000 / 100e5
        p["leak_m3_s_pa_at_40c"] = float(q[LEAK])
    elif name == "cylinder_friction":
        q[LUGRE] = 1.0
        q[FC] = p["coulomb_n"] = _u(rng, 500, 2000)
        q[FS] = p["static_n"] = q[FC] * _u(rng, 1.2, 2.0)
        q[VS] = p["stribeck_m_s"] = _u(rng, 0.005, 0.02)
        q[SIG0], q[SIG1] = 1e6, 1000.0
    elif name == "spool_dynamics":
        q[SPOOL] = 1.0
        q[WN] = 2 * np.pi * _u(rng, 3, 12)
        q[ZETA] = p["damping_ratio"] = _u(rng, 0.5, 1.0)
        q[SVMAX] = p["max_spool_speed_per_s"] = _u(rng, 4.0, 10.0)
        p["natural_freq_hz"] = float(q[WN] / 2 / np.pi)
    elif name == "valve_deadband":
        q[OVL] = _u(rng, 0.05, 0.2)
        p["overlap_pct"] = float(100 * q[OVL])
    elif name == "pump_control_dynamics":
        q[PTAU] = _u(rng, 0.05, 0.3)
        q[PRATE] = _u(rng, 3.0, 10.0)  # full stroke in 0.1-0.33 s at most
        p["time_constant_ms"], p["max_rate_per_s"] = float(1e3 * q[PTAU]), float(q[PRATE])
    elif name == "hose_compliance":
        q[EWALL] = _u(rng, 0.2, 1.0) * 1e9
        p["wall_modulus_gpa"] = float(q[EWALL] / 1e9)
    elif name == "sensor_lag":
        sens = {"delay_s": _u(rng, 0.005, 0.04), "filter_hz": _u(rng, 3.0, 10.0)}
        p = {"delay_ms": 1e3 * sens["delay_s"], "filter_hz": sens["filter_hz"]}
    elif name == "load_variation":
        q[K1] = float(rng.choice([-1, 1]) * _u(rng, 5e3, 15e3))
        q[K2] = _u(rng, -4e4, 4e4)  # curvature of the lever: +-2.5 kN over the stroke
        p["slope_n_per_mm"], p["curvature_n_per_mm2"] = float(q[K1] / 1e3), float(q[K2] / 1e6)
    elif name == "periodic_load":
        q[PAMP] = p["amplitude_n"] = _u(rng, 800, 2000)
        q[PFREQ] = p["frequency_hz"] = _u(rng, 0.3, 2.0)
    elif name == "blocked_return":
        q[KRET] = _u(rng, 0.5, 0.8) * q[KV]
        p["restriction_vs_edge"] = float(q[KRET] / q[KV])
    elif name == "cross_port_leak":
        q[XLEAK] = p["leak_m3_s_pa"] = _u(rng, 1.5e-12, 4e-12)
    else:
        raise ValueError(name)
    return p, sens


def _tolerances(rng: np.random.Generator) -> dict[str, float]:
    keys = ("mass", "gravity", "friction", "valve", "vol_a", "vol_b", "vol_line")
    return {k: 1.0 + _u(rng, -TOLERANCE, TOLERANCE) for k in keys}


def _from_plant(cmds: Recording, names: list[str], tol: dict, rng) -> tuple[dict, dict]:
    q = nominal(tol)
    params, sens = {}, {}
    for n in names:
        params[n], s = alternative(n, q, rng)
        sens.update(s)
    c = {k: cmds[k] for k in COMMAND_NAMES}
    rec = run(cmds.t, c["SpoolCmd"], c["PumpDispCmd"], c["EngineSpeed"], c["OilTemp"], q)
    cols = {**{k: np.round(v, 2) for k, v in c.items()}, **sensors(rec, rng, **sens)}
    return cols, params


def _from_sim(cmds: Recording, names: list[str], tol: dict, rng, seed: int):
    m = load_machine()
    m = m.with_changes(
        mass_kg=m.load.mass_kg * tol["mass"],
        gravity_load_n=m.load.gravity_load_n * tol["gravity"],
        viscous_friction_n_s_m=m.load.viscous_friction_n_s_m * tol["friction"],
        valve_rated_flow_m3_s=m.valve.valve_rated_flow_m3_s * tol["valve"],
        dead_volume_a_m3=m.cylinder.dead_volume_a_m3 * tol["vol_a"],
        dead_volume_b_m3=m.cylinder.dead_volume_b_m3 * tol["vol_b"],
        line_volume_m3=m.line.line_volume_m3 * tol["vol_line"],
    )
    params = {n: catalogue_params(n, rng) for n in names}
    fx = [Effect.make(n, **params[n]) for n in names]
    rec = simulate(cmds, m, effects=fx, seed=seed)
    keep = (*COMMAND_NAMES, "PP", "PA", "PB", "QP", "RodPos")
    return {k: rec[k] for k in keep}, params


def cases(per_effect: int, n_none: int, n_unexplained: int, n_pairs: int) -> list[dict]:
    out: list[dict] = []
    for name in EFFECTS:
        for i in range(per_effect):
            gen = "catalogue" if i % 2 == 0 else "alternative"
            out.append({"kind": "effect", "truth": name, "second": None, "generator": gen})
    for i in range(n_none):
        gen = "catalogue" if i % 2 == 0 else "alternative"
        out.append({"kind": "none", "truth": "none", "second": None, "generator": gen})
    for i in range(n_unexplained):
        d = DISTURBANCES[i % len(DISTURBANCES)]
        out.append(
            {
                "kind": "unexplained",
                "truth": "unexplained",
                "disturbance": d,
                "second": None,
                "generator": "alternative",
            }
        )
    for i in range(n_pairs):
        a, b = PAIRS[i % len(PAIRS)]
        gen = "catalogue" if i % 2 == 0 else "alternative"
        out.append({"kind": "pair", "truth": a, "second": b, "generator": gen})
    return out


def generate(
    data_dir: Path,
    labels_path: Path,
    plan: list[dict],
    duration_s: float,
    seed: int,
    progress: Callable[[str], None] = print,
) -> None:
    """Write one CSV per case into ``data_dir`` (shuffled names) and the labels apart."""
    data_dir.mkdir(parents=True, exist_ok=True)
    order = np.random.default_rng(seed).permutation(len(plan))
    labels = {}
    for k, i in enumerate(order):
        case = dict(plan[i])
        case_seed = seed * 1000 + k
        rng = np.random.default_rng(case_seed)
        cmds = make_cycle("boom", duration_s, case_seed)
        tol = _tolerances(rng)
        names = {
            "effect": [case["truth"]],
            "pair": [case["truth"], case["second"]],
            "none": [],
            "unexplained": [case.get("disturbance")],
        }[case["kind"]]
        if case["generator"] == "catalogue":
            cols, params = _from_sim(cmds, names, tol, rng, case_seed)
        else:
            cols, params = _from_plant(cmds, names, tol, rng)
        name = f"rec_{k:03d}.csv"
        write_csv(data_dir / name, Recording(cmds.t, cols, source=name))
        labels[name] = {**case, "params": params, "tolerance": tol, "seed": case_seed}
        progress(f"generated {name}")
    labels_path.parent.mkdir(parents=True, exist_ok=True)
    labels_path.write_text(json.dumps(labels, indent=2) + "\n")
