"""What the machine's transducers, its controller and the CAN logger make of the plant.

Pressures, flow and stroke are 4-20 mA transmitters (a zero offset within +-0.5 % of full
scale, noise, their own response), read by a 12-bit ADC over 0-25 mA and sent on CAN at
the DBC's resolution every 10 ms; the logger's rows carry a few tenths of a millisecond of
jitter and each frame is up to 2 ms old when its row is written. EngineSpeed is the ECU's
mean over its last 10 ms; OilTemp an NTC in a thermowell (20 s), sent at 1 Hz."""

from __future__ import annotations

import numba
import numpy as np
from scipy.signal import lfilter

from benchmarks.gap_fourth.kernel import OUT_NAMES

COL = {name: i for i, name in enumerate(OUT_NAMES)}
FULL_SCALE = {"PP": 400.0, "PA": 400.0, "PB": 400.0, "QP": 60.0, "RodPos": 500.0}
NOISE = {"PP": 0.3, "PA": 0.3, "PB": 0.3, "QP": 0.1, "RodPos": 0.5}  # rms, signal units
RESPONSE_S = {"PP": 0.0015, "PA": 0.0015, "PB": 0.0015, "QP": 0.006, "RodPos": 0.002}
ADC_LSB_MA = 25.0 / 4096.0
DROPOUT = 1e-4  # share of frames the logger misses (an empty field)


def first_order(x: np.ndarray, tau_s: float, dt_s: float = 1e-3) -> np.ndarray:
    """A first-order lag, exact for a signal held over each sample."""
    if tau_s <= 0.0:
        return x.copy()
    a = np.exp(-dt_s / tau_s)
    y, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])
    return y


@numba.njit(cache=True)
def varying_lag(x, tau_s, dt_s):
    """A first-order lag whose time constant changes sample by sample (a snubber whose
    laminar restriction follows the oil's viscosity)."""
    y = np.empty_like(x)
    y[0] = x[0]
    for i in range(1, x.size):
        a = np.exp(-dt_s / tau_s[i])
        y[i] = a * y[i - 1] + (1.0 - a) * x[i]
    return y


def true_signals(trace: np.ndarray) -> dict[str, np.ndarray]:
    """The quantities the transducers sense, in signal units, at 1 ms."""
    return {
        "PP": trace[:, COL["PP"]] / 1e5,
        "PA": trace[:, COL["PA"]] / 1e5,
        "PB": trace[:, COL["PB"]] / 1e5,
        "QP": trace[:, COL["QP"]] * 60000.0,
        "RodPos": trace[:, COL["x1"]] * 1000.0,
    }


def transmitter(
    rng: np.random.Generator,
    name: str,
    x: np.ndarray,
    zero_pct: float,
    gain: float = 1.0,
    offset: float = 0.0,
) -> np.ndarray:
    """A 4-20 mA transmitter (span `gain`, zero `offset` in signal units plus its own
    zero error in % of full scale), the ADC and the CAN signal's resolution and range."""
    fs = FULL_SCALE[name]
    value = gain * x + offset + zero_pct / 100.0 * fs
    ma = 4.0 + 16.0 * value / fs + rng.normal(0.0, 16.0 * NOISE[name] / fs, x.size)
    ma = np.round(ma / ADC_LSB_MA) * ADC_LSB_MA
    read = np.clip((ma - 4.0) / 16.0 * fs, 0.0, fs)
    return np.round(read * 100.0) / 100.0


def frame_times(rng: np.random.Generator, rows_t: np.ndarray) -> np.ndarray:
    """When each row's frame was sampled (s): up to 2 ms before the row is written."""
    return rows_t - rng.uniform(0.0, 0.002, rows_t.size)


def sample(trace_1ms: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    grid = np.arange(trace_1ms.size) * 1e-3
    return np.interp(t_s, grid, trace_1ms)


def engine_speed(we_1ms: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """The ECU's speed: the mean over the 10 ms before each instant (rpm, 0.125 rpm)."""
    rpm = we_1ms * 60.0 / (2.0 * np.pi)
    c = np.concatenate([[0.0], np.cumsum(rpm)])
    k = np.clip(np.floor(t_s * 1000.0).astype(np.int64), 10, rpm.size)
    mean = (c[k] - c[k - 10]) / 10.0
    return np.round(mean * 8.0) / 8.0


def oil_temp(
    rng: np.random.Generator, temp_1ms: np.ndarray, rows_t: np.ndarray, offset_c: float
) -> np.ndarray:
    """The NTC reading, sent once a second and held by the logger (0.03125 degC)."""
    sensed = first_order(temp_1ms, 20.0) + offset_c
    phase = float(rng.uniform(0.0, 1.0))
    sent_at = np.floor(rows_t - phase) + phase
    val = sample(sensed, np.maximum(sent_at, 0.0))
    return np.round(val / 0.03125) * 0.03125


def commands(lever_1ms: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """A command as the controller last set it (held per millisecond), 0.01 %."""
    k = np.clip(np.floor(t_s * 1000.0).astype(np.int64), 0, lever_1ms.size - 1)
    return np.round(lever_1ms[k] * 100.0 * 100.0) / 100.0


def dropouts(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(size=n) < DROPOUT
