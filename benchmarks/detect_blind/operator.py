"""An operator at the lever: moves, holds, pauses and fine work, closed loop on the boom.

The operator looks at where the boom is (lowering when it is high, raising when it is low),
so a run of hours covers the stroke instead of sitting on one end stop. Styles differ in
lever amplitude, how fast the lever moves, how long holds last and how often the operator
pauses or works finely; now and then a move runs on into an end stop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import plant
from .params import IDX

SAMPLE_S = plant.SAMPLE_S


@dataclass(frozen=True)
class Style:
    """Lever habits: shares of full lever, %/s as a share per second, seconds."""

    amplitude: tuple[float, float]
    rate_per_s: tuple[float, float]
    move_s: tuple[float, float]
    hold_s: tuple[float, float]
    pause_p: float  # chance that a segment is a pause
    pause_s: tuple[float, float]
    fine_p: float  # chance that a move is fine work (10-30 % lever)
    stop_p: float  # chance that a move runs on into the end stop


STYLES = {
    "aggressive": Style((0.6, 1.0), (3.0, 5.0), (0.3, 1.5), (0.2, 1.2), 0.05, (3, 15), 0.05, 0.08),
    "gentle": Style((0.3, 0.7), (0.8, 1.5), (0.5, 2.5), (0.8, 3.0), 0.10, (5, 30), 0.15, 0.03),
    "fine": Style((0.25, 0.5), (0.5, 1.2), (0.8, 4.0), (0.5, 2.5), 0.10, (5, 20), 0.6, 0.0),
    "mixed": Style((0.3, 1.0), (1.0, 4.0), (0.3, 2.5), (0.3, 3.0), 0.08, (3, 40), 0.2, 0.05),
}


def _ramp(level: float, n: int, start: float, rate_per_sample: float) -> np.ndarray:
    """Rate-limited lever from `start` toward `level` over n samples."""
    steps = start + np.sign(level - start) * rate_per_sample * np.arange(1, n + 1)
    return np.minimum(steps, level) if level >= start else np.maximum(steps, level)


def _move(rng: np.random.Generator, style: Style, xi: float) -> np.ndarray:
    """Lever samples of one move and the hold after it (shares of full lever)."""
    up_p = 0.95 if xi < 0.3 else 0.05 if xi > 0.7 else 0.5
    sign = 1.0 if rng.random() < up_p else -1.0
    fine = rng.random() < style.fine_p
    amp = rng.uniform(0.1, 0.3) if fine else rng.uniform(*style.amplitude)
    move_s = rng.uniform(*style.move_s)
    if rng.random() < style.stop_p:
        move_s += 5.0  # long enough to reach the stop from most places
        sign = 1.0 if xi < 0.5 else -1.0
    rate = rng.uniform(*style.rate_per_s) * SAMPLE_S
    n_ramp = int(np.ceil(amp / rate)) + 1
    n_move = max(int(move_s / SAMPLE_S), 1)
    up = _ramp(sign * amp, n_ramp, 0.0, rate)
    level = np.full(n_move, sign * amp)
    down = _ramp(0.0, n_ramp, sign * amp, rate)
    hold = np.zeros(int(rng.uniform(*style.hold_s) / SAMPLE_S))
    return np.concatenate([up, level, down, hold])


def segment(rng: np.random.Generator, style: Style, xi: float) -> np.ndarray:
    """The operator's next lever samples, knowing the boom's stroke share xi."""
    if rng.random() < style.pause_p:
        return np.zeros(int(rng.uniform(*style.pause_s) / SAMPLE_S))
    return _move(rng, style, xi)


@dataclass
class Trace:
    """A run at 100 Hz: commands, oil temperature and the plant's true states."""

    spool: np.ndarray  # share of full lever
    disp: np.ndarray  # share
    speed_rpm: np.ndarray
    temp_c: np.ndarray
    state: np.ndarray  # (n, plant.N_STATE)


def operate(
    p: np.ndarray,
    style: Style,
    duration_s: float,
    temp_c,
    rng: np.random.Generator,
    fault: str = "normal",
    severity: float = 0.0,
    onset_s: float = 0.0,
    payload: float = 1.0,
    speed_set_rpm: float = 2200.0,
) -> Trace:
    """Run the plant for duration_s with this operator; temp_c(t_array) gives the oil's."""
    n = int(round(duration_s / SAMPLE_S))
    stroke = p[IDX["stroke_m"]]
    s = plant.initial_state(p, rng.uniform(0.1, 0.9) * stroke, payload)
    spool = np.empty(n)
    state = np.empty((n, plant.N_STATE))
    speed = np.empty(n)
    t = np.arange(n) * SAMPLE_S
    temp = np.asarray(temp_c(t), dtype=np.float64)
    disp = np.ones(n)
    sev = np.where(t >= onset_s, severity, 0.0) if fault != "normal" else np.zeros(n)
    # The operator decides segment by segment on the boom's position: run those pieces.
    k = 0
    while k < n:
        seg = segment(rng, style, float(s[plant.X] / stroke))
        m = min(len(seg), n - k)
        spool[k : k + m] = seg[:m]
        # The engine droops a little with the lever (load) around its governor's set speed.
        speed[k : k + m] = speed_set_rpm - 30.0 * np.abs(seg[:m]) + rng.normal(0.0, 2.0, m)
        state[k : k + m] = plant.simulate(
            p,
            s,
            t[k],
            spool[k : k + m],
            disp[k : k + m],
            speed[k : k + m],
            temp[k : k + m],
            sev[k : k + m],
            fault,
            payload,
        )
        k += m
    return Trace(spool, disp, speed, temp, state)
