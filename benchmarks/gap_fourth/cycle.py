"""An operator's boom work at 1 ms: raise, hold, lower, fine moves, stops and pauses.

The operator aims at rod positions by eye with a rough idea of the boom's speed (the
plant's real speed differs), so positions drift and now and then reach a stop; the
machine controller sets the pump's displacement command from the lever."""

from __future__ import annotations

import numpy as np

MS = 1000  # samples per second of the command trace


def _speed_guess(lever: float) -> float:
    """The operator's idea of the rod speed (m/s) at a lever (0..1)."""
    return 0.13 * min(1.0, 2.2 * lever) ** 1.5


def _move(rng: np.random.Generator, sign: float, lever: float, dist_m: float) -> list:
    """Ramps and a plateau (as (duration_s, start value, end value) pieces)."""
    up = float(rng.uniform(0.15, 0.6))
    down = float(rng.uniform(0.1, 0.4))
    speed = _speed_guess(lever) * float(rng.uniform(0.8, 1.25))
    flat = max(dist_m / speed - 0.5 * (up + down), 0.05)
    return [(up, 0.0, sign * lever), (flat, sign * lever, sign * lever), (down, sign * lever, 0.0)]


def _action(rng: np.random.Generator, pos: float) -> tuple[list, float]:
    """One of the operator's actions from the believed rod position `pos` (m)."""
    r = rng.uniform()
    hold = [(float(rng.uniform(0.8, 4.0)), 0.0, 0.0)]
    if r < 0.1:  # a pause
        return [(float(rng.uniform(4.0, 12.0)), 0.0, 0.0)], pos
    if r < 0.22:  # to a stop and pushing against it
        top = rng.uniform() < 0.5
        lever = float(rng.uniform(0.5, 1.0))
        dist = (0.5 - pos) if top else pos
        pieces = _move(rng, 1.0 if top else -1.0, lever, dist + 0.03)
        pieces.insert(2, (float(rng.uniform(0.5, 2.0)), pieces[1][1], pieces[1][1]))
        return pieces + hold, 0.5 if top else 0.0
    if r < 0.34:  # a fine move
        lever = float(rng.uniform(0.12, 0.3))
        sign = 1.0 if (rng.uniform() < 0.5 and pos < 0.45) or pos < 0.05 else -1.0
        dist = float(rng.uniform(0.01, 0.05))
    else:  # raise or lower to a target by eye
        target = float(rng.uniform(0.03, 0.47))
        if abs(target - pos) < 0.05:
            target = 0.47 if pos < 0.25 else 0.03
        sign = 1.0 if target > pos else -1.0
        lever = float(rng.uniform(0.3, 1.0))
        dist = abs(target - pos)
    new = min(max(pos + sign * dist, 0.0), 0.5)
    return _move(rng, sign, lever, dist) + hold, new


def _render(pieces: list, n: int) -> np.ndarray:
    out = np.zeros(n)
    i = 0
    for dur, a, b in pieces:
        m = max(int(round(dur * MS)), 1)
        j = min(i + m, n)
        out[i:j] = np.linspace(a, b, m, endpoint=False)[: j - i]
        i = j
        if i >= n:
            break
    return out


def spool_commands(
    rng: np.random.Generator, duration_s: float, pre_s: float, rod0_m: float
) -> np.ndarray:
    """The lever (-1..1) at 1 ms over pre_s of rest and duration_s of work."""
    n = int(round((duration_s + pre_s) * MS))
    pieces = [(pre_s + float(rng.uniform(1.0, 3.0)), 0.0, 0.0)]
    pos, total = rod0_m, pieces[0][0]
    while total < duration_s + pre_s:
        more, pos = _action(rng, pos)
        pieces += more
        total += sum(d for d, _, _ in more)
    return _render(pieces, n)


def pump_commands(lever: np.ndarray, mode: str) -> np.ndarray:
    """PumpDispCmd (0..1) from the lever: `full` 100 %, `matching` 40 % + |lever|
    (rate-limited to 300 %/s by the controller), `eco` 85 %."""
    if mode == "full":
        return np.ones_like(lever)
    if mode == "eco":
        return np.full_like(lever, 0.85)
    want = np.clip(0.4 + np.abs(lever), 0.0, 1.0)
    out = np.empty_like(want)
    step = 3.0 / MS
    cur = want[0]
    for i, w in enumerate(want):
        cur += min(max(w - cur, -step), step)
        out[i] = cur
    return out
