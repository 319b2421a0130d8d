"""What the controller reads: the true traces (one a millisecond) through this machine's
transducers, sampled every 10 ms with a few milliseconds of jitter.

- Pressures: ratiometric 0.5-4.5 V transducers for 0-400 bar on a 12-bit ratiometric ADC
  (the supply cancels unless the sensor's supply and the ADC's reference differ: a gain
  and an offset), electrical noise, clipped at the output's 0.5 V floor; 0.05 bar on CAN.
- Pump flow: a gear flow meter's pulses (0.02 cm^3 each) counted between two samples and
  divided by the measured interval; the count does not know the direction.
- Engine speed: the mean over the last 10 ms (teeth counted), 0.125 rpm on CAN.
- Oil temperature: read once a second, whole degrees on CAN.
- Rod position: magnetostrictive, 0.1 mm resolution, clipped to the stroke.
Withheld sensor effects act here: a CAN gateway's transport delay and the pressure ports'
snubbers (sensor lag); a reading's gain and offset (sensor calibration).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import bilinear, lfilter, lfilter_zi

PERIOD_S = 0.01
PULSE_M3 = 0.02e-6


@dataclass(frozen=True)
class SensorSet:
    """The transducers of one machine, and any withheld effect on them."""

    gain: dict[str, float] = field(default_factory=dict)  # signal -> gain
    offset: dict[str, float] = field(default_factory=dict)  # signal -> offset, signal unit
    gateway_delay_ms: int = 0
    snubber_hz: float = 0.0  # 0: no snubber
    snubber_zeta: float = 0.8


def sample_times(rng: np.random.Generator, duration_s: float) -> np.ndarray:
    """Row times: every 10 ms with a task jitter of up to +-2 ms (s)."""
    n = int(round(duration_s / PERIOD_S))
    t = np.arange(n) * PERIOD_S + rng.uniform(-0.002, 0.002, n)
    t[0] = 0.0
    return np.clip(t, 0.0, None)


def _at(trace: np.ndarray, t: np.ndarray) -> np.ndarray:
    """A millisecond trace at the row times (linear interpolation)."""
    return np.interp(t * 1000.0, np.arange(trace.size), trace)


def _snubber(trace: np.ndarray, hz: float, zeta: float) -> np.ndarray:
    """A second-order low-pass (orifice and trapped volume of a snubbed gauge port)."""
    w = 2 * np.pi * hz
    b, a = bilinear([w * w], [1.0, 2 * zeta * w, w * w], fs=1000.0)
    y, _ = lfilter(b, a, trace, zi=lfilter_zi(b, a) * trace[0])
    return y


def _delayed(trace: np.ndarray, ms: int) -> np.ndarray:
    if ms <= 0:
        return trace
    return np.concatenate([np.full(ms, trace[0]), trace[:-ms]])


def pressure(rng, true_pa: np.ndarray, t: np.ndarray, name: str, s: SensorSet) -> np.ndarray:
    """A pressure reading (bar) at the row times."""
    bar = true_pa / 1e5
    if s.snubber_hz > 0:
        bar = _snubber(bar, s.snubber_hz, s.snubber_zeta)
    bar = _delayed(bar, s.gateway_delay_ms)
    bar = _at(bar, t) * s.gain.get(name, 1.0) + s.offset.get(name, 0.0)
    bar = bar + rng.normal(0.0, 0.22, bar.size)
    counts = np.clip(np.round(4095 * (0.1 + 0.8 * bar / 400.0)), 409.5, 4095)
    reading = (counts / 4095 - 0.1) / 0.8 * 400.0
    return np.round(np.clip(reading, 0.0, 400.0) / 0.05) * 0.05


def flow(q_cum_m3: np.ndarray, t: np.ndarray, s: SensorSet) -> np.ndarray:
    """The gear meter's flow (L/min) over each row interval."""
    vol = _delayed(q_cum_m3, s.gateway_delay_ms)
    pulses = np.floor(_at(vol, t) / PULSE_M3)
    dt = np.diff(t, prepend=t[0] - PERIOD_S)
    lpm = np.abs(np.diff(pulses, prepend=pulses[0])) * PULSE_M3 / dt * 60000.0
    lpm = lpm * s.gain.get("QP", 1.0) + s.offset.get("QP", 0.0)
    return np.round(np.clip(lpm, 0.0, 60.0) / 0.05) * 0.05


def engine_speed(rng, speed_rad_s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Mean engine speed over the last 10 ms (rpm), 0.125 rpm steps."""
    rpm = speed_rad_s * 30.0 / np.pi
    mean = np.convolve(rpm, np.full(10, 0.1), mode="full")[: rpm.size]
    mean[:10] = rpm[:10]
    return np.round((_at(mean, t) + rng.normal(0.0, 0.3, t.size)) / 0.125) * 0.125


def oil_temp(true_c: np.ndarray, t: np.ndarray, offset_c: float) -> np.ndarray:
    """Whole degrees, read once a second and held."""
    held = np.floor(t)
    return np.round(_at(true_c, held) + offset_c)


def rod_pos(rng, stroke_m: np.ndarray, t: np.ndarray, s: SensorSet, stroke_mm: float):
    """Rod position (mm) from the retracted end."""
    mm = _at(stroke_m, t) * 1000.0 * s.gain.get("RodPos", 1.0) + s.offset.get("RodPos", 0.0)
    mm = mm + rng.normal(0.0, 0.08, mm.size)
    return np.round(np.clip(mm, 0.0, stroke_mm) / 0.1) * 0.1


def healthy_spread(rng: np.random.Generator) -> SensorSet:
    """Transducers within their data sheets: +-0.3 % gain, +-0.4 bar zero."""
    gain = {k: 1.0 + rng.uniform(-0.003, 0.003) for k in ("PP", "PA", "PB", "QP")}
    offset = {k: rng.uniform(-0.4, 0.4) for k in ("PP", "PA", "PB")}
    return SensorSet(gain=gain, offset=offset)
