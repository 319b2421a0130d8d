"""Transducers: the plant's 1 kHz states read as a user's 100 Hz contract CSV.

Pressure transducers (1 ms electronics), a flow meter (4 ms), an optional sensor lag
(transport delay, first-order time constant, update rate: a reading held between updates)
on the hydraulic transducers, a gain/offset on one reading, white noise, the ranges and
quantisation steps of real CAN signals, OilTemp at 1 Hz, rows with a little jitter."""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from benchmarks.gap_third.plant import BAR

NOISE = {"PP": 0.3, "PA": 0.3, "PB": 0.3, "QP": 0.1, "RodPos": 0.5}
RANGE = {"PP": (0, 400), "PA": (0, 400), "PB": (0, 400), "QP": (0, 60), "RodPos": (0, 500)}
STEP = {
    "PP": 0.05,
    "PA": 0.05,
    "PB": 0.05,
    "QP": 0.05,
    "RodPos": 0.1,
    "SpoolCmd": 0.1,
    "PumpDispCmd": 0.1,
    "EngineSpeed": 0.125,
    "OilTemp": 1.0,
}
BASE_TAU_MS = {"PP": 1.0, "PA": 1.0, "PB": 1.0, "QP": 4.0, "RodPos": 0.0}


def first_order(x: np.ndarray, tau_ms: float, fs: float = 1000.0) -> np.ndarray:
    """Exact discretisation of 1 / (tau s + 1), started at rest on x[0]."""
    if tau_ms <= 0:
        return x.copy()
    a = np.exp(-1000.0 / (tau_ms * fs))
    y, _ = lfilter([1 - a], [1, -a], x, zi=[a * x[0]])
    return y


def lagged(x: np.ndarray, delay_ms: float, tau_ms: float, update_ms: float) -> np.ndarray:
    """A sensor lag on a 1 kHz trace: delay, then first-order, then held between updates."""
    d = int(round(delay_ms))
    y = np.concatenate([np.full(d, x[0]), x[: len(x) - d]]) if d > 0 else x.copy()
    y = first_order(y, tau_ms)
    u = max(1, int(round(update_ms)))
    return y[(np.arange(len(y)) // u) * u]


def read(
    states: np.ndarray,
    inputs: dict,
    sens: dict,
    effect: str,
    rodpos: bool,
    rng: np.random.Generator,
) -> dict[str, np.ndarray]:
    """Columns of the contract CSV (units of the contract) from the plant's 1 kHz output."""
    true = {
        "PP": states[:, 0] / BAR,
        "PA": states[:, 1] / BAR,
        "PB": states[:, 2] / BAR,
        "QP": states[:, 3] * 60000.0,
        "RodPos": states[:, 4] * 1e3,
    }
    n = len(inputs["spool"])
    jitter = np.clip(rng.normal(0, 0.8, n), -3, 3)  # ms
    t_ms = np.arange(n) * 10.0 + jitter
    t_ms[0] = 0.0
    idx = np.clip(np.round(t_ms).astype(int), 0, len(states) - 1)
    cols = {"t": t_ms / 1000.0}
    cols["SpoolCmd"] = 100 * inputs["spool"]
    cols["PumpDispCmd"] = 100 * inputs["disp"]
    cols["EngineSpeed"] = states[idx, 8]
    temp_1hz = inputs["temp"][(np.arange(n) // 100) * 100]
    cols["OilTemp"] = temp_1hz
    names = ["PP", "PA", "PB", "QP"] + (["RodPos"] if rodpos else [])
    for name in names:
        y = first_order(true[name], BASE_TAU_MS[name])
        if effect == "sensor_lag" and name in sens["signals"]:
            y = lagged(y, sens["delay_ms"], sens["time_constant_ms"], sens["update_ms"])
        if effect == "sensor_calibration" and name == sens["signal"]:
            y = sens["gain"] * y + sens["offset"]
        cols[name] = np.clip(y[idx] + rng.normal(0, NOISE[name], n), *RANGE[name])
    for name, step in STEP.items():
        if name in cols:
            cols[name] = np.round(cols[name] / step) * step
    return cols
