"""One recording from one key entry: the machine, its effect, the operator, the sensors.

Everything a recording depends on is in its key entry (the drawn tolerances, the effect's
parameters, the conditions and the seed of the operator and the noise), so the key alone
rebuilds the same file bit for bit."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.gap_fourth import cycle, effects, sensors
from benchmarks.gap_fourth import params as pr
from benchmarks.gap_fourth import plant as pl
from benchmarks.gap_fourth.kernel import integrate

PRE_S = 3.0  # the machine settles before the logger starts
DT_S = 1e-4  # RK4 step
MEASURED = ("PP", "PA", "PB", "QP", "RodPos")


def machine(entry: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
    """The entry's parameter vector and sensor settings."""
    p = pr.apply_tolerances(pr.nominal(), entry["tolerances"])
    p[pl.T_AMB] = entry["conditions"]["ambient_c"]
    return effects.apply(entry["effect"], entry["params"], p)


def simulate(entry: dict[str, Any], rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The plant's 1 ms trace with the commands that drove it."""
    p, sens = machine(entry)
    cond = entry["conditions"]
    dur = float(entry["duration_s"])
    lever = cycle.spool_commands(rng, dur, PRE_S, cond["rod0_mm"] / 1000.0)
    disp = cycle.pump_commands(lever, cond["pump_mode"])
    noise = sensors.first_order(rng.normal(0.0, 6.0, lever.size), 0.005)
    x0 = pr.initial_state(p, cond["rod0_mm"] / 1000.0, cond["oil_start_c"])
    trace, _ = integrate(p, x0, lever, disp, noise, DT_S, int(round(1e-3 / DT_S)))
    return {"trace": trace, "lever": lever, "disp": disp, "p": p, "sens": sens}


def _viscosity_ratio(p: np.ndarray, temp_c: np.ndarray) -> np.ndarray:
    nu = 10.0 ** (10.0 ** (p[pl.WAL_A] - p[pl.WAL_B] * np.log10(temp_c + 273.15))) - 0.7
    return nu * 1e-6 * p[pl.RHO] / p[pl.MU_REF]


def sensed(sim: dict[str, Any]) -> dict[str, np.ndarray]:
    """Each transducer's output before sampling (signal units, 1 ms): its own response,
    and a withheld sensor lag (snubbers on the pressures, a gateway's delay)."""
    true = sensors.true_signals(sim["trace"])
    s = sim["sens"]
    temp = sim["trace"][:, sensors.COL["T"]]
    out = {}
    for name in MEASURED:
        y = sensors.first_order(true[name], sensors.RESPONSE_S[name])
        if s["snubber_ms"] > 0.0 and name in ("PP", "PA", "PB"):
            tau = s["snubber_ms"] / 1000.0 * _viscosity_ratio(sim["p"], temp)
            y = sensors.varying_lag(y, tau, 1e-3)
        d = int(s["delay_ms"])
        if d > 0 and name in ("PP", "PA", "PB", "QP"):
            y = np.concatenate([np.full(d, y[0]), y[:-d]])
        out[name] = y
    return out


def readings(
    entry: dict[str, Any], sim: dict[str, Any], rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """The logger's columns (contract names and units; NaN where a frame was missed)."""
    n = int(round(float(entry["duration_s"]) * 100))
    t = np.round((np.arange(n) * 0.01 + np.clip(rng.normal(0, 3e-4, n), -1e-3, 1e-3)) * 1e4) / 1e4
    t[0] = 0.0
    inst = t + PRE_S
    cond, s = entry["conditions"], sim["sens"]
    raw = sensed(sim)
    cmd_t = sensors.frame_times(rng, inst)
    cols = {
        "t": t,
        "SpoolCmd": sensors.commands(sim["lever"], cmd_t),
        "PumpDispCmd": sensors.commands(sim["disp"], cmd_t),
        "EngineSpeed": sensors.engine_speed(sim["trace"][:, sensors.COL["we"]], cmd_t),
        "OilTemp": sensors.oil_temp(
            rng, sim["trace"][:, sensors.COL["T"]], inst, cond["temp_offset_c"]
        ),
    }
    frames = {"PP": "press", "PA": "press", "PB": "press", "QP": "flow", "RodPos": "rod"}
    when = {f: sensors.frame_times(rng, inst) for f in ("press", "flow", "rod")}
    lost = {f: sensors.dropouts(rng, n) for f in ("press", "flow", "rod")}
    for name in MEASURED:
        cal = s["cal_signal"] == name
        val = sensors.transmitter(
            rng,
            name,
            sensors.sample(raw[name], when[frames[name]]),
            cond["zero_pct"][name],
            s["cal_gain"] if cal else 1.0,
            s["cal_offset"] if cal else 0.0,
        )
        val[lost[frames[name]]] = np.nan
        cols[name] = val
    if not cond["rodpos"]:
        del cols["RodPos"]
    return cols


FORMATS = {
    "t": "%.4f",
    "SpoolCmd": "%.2f",
    "PumpDispCmd": "%.2f",
    "EngineSpeed": "%.3f",
    "OilTemp": "%.5f",
    "PP": "%.2f",
    "PA": "%.2f",
    "PB": "%.2f",
    "QP": "%.2f",
    "RodPos": "%.2f",
}


def write_csv(path: Path, cols: dict[str, np.ndarray]) -> None:
    names = list(cols)
    text = []
    for name in names:
        fmt = FORMATS[name]
        v = cols[name]
        s = np.char.mod(fmt, np.nan_to_num(v))
        s[np.isnan(v)] = ""
        text.append(s)
    rows = np.stack(text, axis=1)
    with open(path, "w", encoding="ascii", newline="\n") as f:
        f.write(",".join(names) + "\n")
        f.write("\n".join(",".join(r) for r in rows.tolist()) + "\n")


def build(entry: dict[str, Any], out_dir: Path) -> Path:
    """Simulate and write one recording; returns its path."""
    rng = np.random.default_rng(entry["noise_seed"])
    sim = simulate(entry, rng)
    path = out_dir / f"{entry['name']}.csv"
    write_csv(path, readings(entry, sim, rng))
    return path
