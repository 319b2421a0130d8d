"""Sensor model: lag (the ``sensor_lag`` effect), noise, range limits and DBC quantisation.

Works on the plant's fine record (true SI values, about 1 kHz) and returns 100 Hz samples
in the contract's units (bar, L/min, mm).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.signal import lfilter


@dataclass(frozen=True)
class SensorParams:
    """Noise (rms) and ranges of the reference machine's sensors (docs/reference/contracts.md)."""

    pressure_noise_bar: float = 0.3
    flow_noise_lpm: float = 0.1
    rodpos_noise_mm: float = 0.5
    pressure_range_bar: tuple[float, float] = (0.0, 400.0)
    flow_range_lpm: tuple[float, float] = (0.0, 60.0)
    rodpos_range_mm: tuple[float, float] = (0.0, 500.0)
    oil_temp_period_s: float = 1.0


@lru_cache(maxsize=1)
def dbc_resolutions() -> dict[str, tuple[float, float]]:
    """(scale, offset) of every signal in the shipped DBC: the bus's resolution."""
    from monitor.codec.dbc import load_dbc  # cantools only when the bus's resolution is asked

    db = load_dbc()
    return {s.name: (float(s.scale), float(s.offset)) for m in db.messages for s in m.signals}


def quantise(name: str, values: np.ndarray) -> np.ndarray:
    """Round to the DBC resolution of ``name`` (what a decoded frame can carry)."""
    scale, offset = dbc_resolutions()[name]
    return np.round((values - offset) / scale) * scale + offset


def lag(t_s: np.ndarray, values: np.ndarray, delay_s: float, time_constant_s: float) -> np.ndarray:
    """First-order filter (exact discretisation) then a pure delay, on a uniform axis."""
    out = values
    if time_constant_s > 0.0:
        dt = float(t_s[1] - t_s[0])
        a = np.exp(-dt / time_constant_s)
        out, _ = lfilter([1.0 - a], [1.0, -a], out, zi=[a * out[0]])
    if delay_s > 0.0:
        out = np.interp(t_s - delay_s, t_s, out)  # holds the first value before t=0
    return out


def sample_hold(t_s: np.ndarray, values: np.ndarray, period_s: float) -> np.ndarray:
    """A slow sensor: each row shows the last update, updates every ``period_s``."""
    idx = np.floor(t_s / period_s + 1e-9) * period_s
    return np.interp(idx, t_s, values)


def measure(
    name: str,
    true_values: np.ndarray,
    noise_rms: float,
    value_range: tuple[float, float],
    rng: np.random.Generator | None,
) -> np.ndarray:
    """Noise, saturation at the sensor's range, then the bus's quantisation."""
    out = true_values
    if rng is not None and noise_rms > 0.0:
        out = out + rng.normal(0.0, noise_rms, size=out.shape)
    return quantise(name, np.clip(out, *value_range))
