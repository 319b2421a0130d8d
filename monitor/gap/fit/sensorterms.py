"""Sensor terms of ``suggestion``: a gain, an offset or a delay of one measured signal,
fitted on the calibrated simulator's readings alone (no plant runs: a reading error does
not change the physics).

The sensors clip at zero (as ``predict.sense`` models them, unless the recording reads below
it), so rows where the recording reads at the sensor's zero are left out of the gain and
offset fits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.signals import MEASURED_NAMES, UNITS

#: Delays tried (s): 0 to 150 ms in 5 ms steps (a grid: the objective is not smooth in a
#: delay shorter than the 10 ms sample period).
DELAYS_S = np.arange(1, 31) * 5e-3
GAIN_RANGE = (0.5, 1.5)


@dataclass(frozen=True)
class SensorTerm:
    kind: str  # sensor_gain, sensor_offset, sensor_delay
    signal: str
    coefficient: float  # gain (-), offset (signal unit) or delay (ms)

    @property
    def key(self) -> str:
        return f"{self.kind}:{self.signal}"

    @property
    def unit(self) -> str:
        return {"sensor_gain": "-", "sensor_offset": UNITS[self.signal]}.get(self.kind, "ms")

    def description(self) -> str:
        if self.kind == "sensor_gain":
            return f"{self.signal} sensor reads {self.coefficient:.4g} x the true value"
        if self.kind == "sensor_offset":
            return f"{self.signal} sensor reads {self.coefficient:+.3g} {self.unit} off"
        return f"{self.signal} sensor reading delayed by {self.coefficient:.0f} ms"

    def apply(
        self, prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]
    ) -> dict[str, np.ndarray]:
        """``pred`` (simulated readings) as this sensor would read them."""
        x = pred[self.signal]
        if self.kind == "sensor_gain":
            y = prep.reading(self.signal, self.coefficient * x)
        elif self.kind == "sensor_offset":
            y = prep.reading(self.signal, x + self.coefficient)
        else:
            y = _delayed(prep, segments, x, self.coefficient * 1e-3)
        return {**pred, self.signal: y}


def _delayed(
    prep: Prepared, segments: Sequence[Segment], x: np.ndarray, delay_s: float
) -> np.ndarray:
    """``x`` delayed by ``delay_s`` within each segment (held at its first value before)."""
    out = x.copy()
    for seg in segments:
        rows = slice(seg.start, seg.stop + 1)
        t = prep.t[rows]
        out[rows] = np.interp(t - delay_s, t, x[rows])
    return out


def _rows(segments: Sequence[Segment]) -> np.ndarray:
    return np.concatenate([np.arange(s.score_from, s.stop) for s in segments])


def fit_sensor_terms(
    prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]
) -> list[SensorTerm]:
    """Gain, offset and delay of each measured signal, fitted alone on ``segments``
    against the simulated readings ``pred`` (closed form; the delay on a grid)."""
    rows = _rows(segments)
    out = []
    for signal in MEASURED_NAMES:
        x, y = pred[signal][rows], prep.meas[signal][rows]
        ok = np.isfinite(x) & np.isfinite(y) & prep.off_zero(signal, y)
        if ok.sum() < 10:
            continue
        xx = float(x[ok] @ x[ok])
        gain = float(x[ok] @ y[ok]) / xx if xx > 0 else 1.0
        out.append(SensorTerm("sensor_gain", signal, float(np.clip(gain, *GAIN_RANGE))))
        out.append(SensorTerm("sensor_offset", signal, float(np.mean(y[ok] - x[ok]))))

        costs = [
            float(np.mean((_delayed(prep, segments, pred[signal], d)[rows][ok] - y[ok]) ** 2))
            for d in DELAYS_S
        ]
        out.append(SensorTerm("sensor_delay", signal, 1e3 * float(DELAYS_S[int(np.argmin(costs))])))
    return out
