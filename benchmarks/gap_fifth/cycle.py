"""An operator's boom work, one value a millisecond: spool, displacement limit, engine set
point, oil temperature and the engine's other loads.

The operator moves the boom in phases of 1-4 s (raise, lower, hold, slow ramps, back and
forth), sometimes onto an end stop and held there; the joystick is rate-limited. A rough
estimate of the rod's place keeps most moves inside the stroke, as an operator watching the
boom would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.signal import lfilter

RATE_PER_S = 1.6  # joystick slew, share of full command per second
RPM_NOMINAL = 2200.0


@dataclass(frozen=True)
class Warmup:
    """Oil temperature: from start_c towards end_c with time constant tau_s."""

    start_c: float
    end_c: float
    tau_s: float

    def at(self, t: np.ndarray) -> np.ndarray:
        return self.end_c - (self.end_c - self.start_c) * np.exp(-t / self.tau_s)


def draw_warmup(rng: np.random.Generator, warm_up: bool | None = None) -> Warmup:
    """A cold start warming up (about half the recordings), else a machine already warm."""
    if warm_up is None:
        warm_up = bool(rng.uniform() < 0.5)
    if warm_up:
        return Warmup(rng.uniform(14.0, 26.0), rng.uniform(50.0, 60.0), rng.uniform(70.0, 160.0))
    start = rng.uniform(38.0, 55.0)
    return Warmup(start, start + rng.uniform(0.0, 4.0), rng.uniform(200.0, 600.0))


def _phase(rng, pos_m: float) -> tuple[str, float, float]:
    """Next phase: kind, spool level (signed), duration (s)."""
    r = rng.uniform()
    if r < 0.30:
        return "hold", 0.0, rng.uniform(0.6, 3.0)
    if r < 0.40:
        return "stop", (1.0 if pos_m < 0.25 else -1.0) * rng.uniform(0.5, 1.0), 0.0
    if r < 0.50:
        return "ramp", (1.0 if pos_m < 0.25 else -1.0) * rng.uniform(0.4, 0.9), rng.uniform(2, 4)
    if r < 0.58:
        return "sweep", rng.uniform(0.25, 0.55), rng.uniform(3.0, 6.0)
    want_up = pos_m < 0.12 or (pos_m < 0.38 and rng.uniform() < 0.5)
    level = min(rng.choice([0.3, 0.45, 0.6, 0.8, 1.0]) * rng.uniform(0.9, 1.1), 1.0)
    return "move", (level if want_up else -level), rng.uniform(1.0, 4.0)


def _speed_estimate(cmd: float) -> float:
    """Rod speed an operator expects (m/s): full pump flow from about 60 % spool."""
    share = min(abs(cmd) / 0.6, 1.0) ** 1.5
    return 0.125 * share if cmd > 0 else -0.18 * share


def spool_profile(rng: np.random.Generator, n_ms: int) -> np.ndarray:
    """The spool command (-1..1) a millisecond, before the joystick slew."""
    cmd = np.zeros(n_ms)
    i, pos = 0, 0.2
    while i < n_ms:
        kind, level, dur = _phase(rng, pos)
        if kind == "stop":
            speed = abs(_speed_estimate(level))
            way = (0.5 - pos) if level > 0 else pos
            dur = way / max(speed, 0.02) + rng.uniform(0.8, 2.5)
        n = max(int(dur * 1000), 1)
        t = np.arange(n) / 1000.0
        if kind == "ramp":
            seg = level * np.minimum(t / (0.5 * dur), 2.0 - t / (0.5 * dur))
        elif kind == "sweep":
            seg = level * np.sin(2 * np.pi * rng.uniform(0.3, 0.9) * t)
        else:
            seg = np.full(n, level)
        seg = seg[: n_ms - i]
        cmd[i : i + seg.size] = seg
        pos = float(np.clip(pos + np.sum([_speed_estimate(c) for c in seg[::50]]) * 0.05, 0, 0.5))
        i += seg.size
    return slew(cmd, RATE_PER_S / 1000.0)


@njit(cache=True)
def slew(x: np.ndarray, step: float) -> np.ndarray:
    """Rate-limit a command to `step` per sample, from 0."""
    out = np.empty_like(x)
    last = 0.0
    for k in range(x.size):
        last += min(max(x[k] - last, -step), step)
        out[k] = last
    return out


def blocks(rng, n_ms: int, base: float, other, share: float) -> np.ndarray:
    """Set point in blocks of 20-60 s: `base`, or for `share` of them a draw of `other()`."""
    out = np.empty(n_ms)
    i = 0
    while i < n_ms:
        n = int(rng.uniform(20.0, 60.0) * 1000)
        out[i : i + n] = other() if rng.uniform() < share else base
        i += n
    return out


def disturbance(rng, n_ms: int, sigma_nm: float = 3.0, tau_s: float = 0.3) -> np.ndarray:
    """The engine's other consumers (fan, pilot pump, other functions): a slow random torque."""
    a = np.exp(-1e-3 / tau_s)
    w = rng.normal(0.0, sigma_nm * np.sqrt(1 - a * a), n_ms)
    return lfilter([1.0], [1.0, -a], w) + 6.0
