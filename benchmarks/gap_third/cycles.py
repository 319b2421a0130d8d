"""Operator-like boom cycles at 100 Hz: raise, hold, lower at various amplitudes, some runs
into the stops, engine speed steps, and an oil warm-up on some recordings."""

from __future__ import annotations

import numpy as np

FS = 100.0


def _ramp(level: np.ndarray, rate_per_s: float) -> np.ndarray:
    """Rate-limit a step sequence (the joystick is not moved instantly)."""
    out = np.empty_like(level)
    step = rate_per_s / FS
    cur = level[0]
    for i, target in enumerate(level):
        cur += min(step, max(-step, target - cur))
        out[i] = cur
    return out


def boom_cycles(duration_s: float, rng: np.random.Generator, warmup: bool) -> dict[str, np.ndarray]:
    """Commands, engine set speed, oil temperature and engine ripple, one row per 10 ms."""
    n = int(round(duration_s * FS))
    spool = np.zeros(n)
    disp = np.ones(n)
    pos = 0.05  # the operator's own idea of the rod position (m)
    i = int(2 * FS)
    disp_level = 1.0
    while i < n:
        target = rng.uniform(-0.03, 0.53) if rng.random() < 0.2 else rng.uniform(0.04, 0.46)
        amp = rng.uniform(0.25, 1.0)
        up = target > pos
        speed = (0.13 if up else 0.15) * min(1.0, 1.3 * amp)
        dur = min(6.0, max(0.4, abs(target - pos) / speed))
        pos = min(0.5, max(0.0, target))
        k = int(dur * FS)
        if rng.random() < 0.15:
            disp_level = rng.uniform(0.6, 1.0)
        spool[i : i + k] = amp if up else -amp
        disp[i : i + k] = disp_level
        i += k + int(rng.uniform(0.8, 4.0) * FS)
    spool = _ramp(spool, rng.uniform(2.5, 10.0))
    n_set = np.full(n, 2200.0)
    if rng.random() < 0.3:  # the operator changes the throttle now and then
        for _ in range(rng.integers(1, 4)):
            a = int(rng.uniform(0, duration_s - 30) * FS)
            n_set[a : a + int(rng.uniform(10, 30) * FS)] = rng.choice([1800.0, 2000.0])
        n_set = _ramp(n_set, 400.0)
    t = np.arange(n) / FS
    if warmup:
        t0, t_end = rng.uniform(15, 25), rng.uniform(50, 60)
        temp = t_end - (t_end - t0) * np.exp(-t / rng.uniform(100, 200))
    else:
        temp = np.full(n, rng.uniform(40, 55)) + 0.5 * np.sin(2 * np.pi * t / duration_s)
    ripple = np.zeros(n)
    e = rng.normal(0.0, 1.5, n)
    for k in range(1, n):  # governor hunting: an AR(1) speed ripple (rpm)
        ripple[k] = 0.9 * ripple[k - 1] + e[k]
    return {"spool": spool, "disp": disp, "n_set": n_set, "temp": temp, "ripple": ripple}
