"""Seeded command profiles at 100 Hz: boom duty cycles, slow ramps and steps.

Each returns a ``Recording`` holding only the commands (SpoolCmd %, PumpDispCmd %,
EngineSpeed rpm, OilTemp degC); the simulator adds the measured signals.
"""

from __future__ import annotations

import numpy as np

from monitor.errors import ConfigError
from monitor.io.recording import Recording
from monitor.signals import SAMPLE_PERIOD_S

CYCLES = ("boom", "boom-cover", "ramp", "step")
RATE_LIMIT_PCT_S = 200.0
#: Share of boom-cycle moves that run into an end stop (normal operation; the detector must
#: learn the stalled regime too).
STOP_VISIT_PROBABILITY = 0.15
#: Training cycles (``boom-cover``): twice the stop visits, and the lever released anywhere
#: from 3 cm short of the stop to 5 cm past it.  A boom cycle releases it well past the stop,
#: after the pressure has built up; an operator now and then releases it during the build-up,
#: and the spool then traps whatever pressures the cylinder had (PA 38 / PB 158 bar at the
#: bottom stop), states a model trained on boom cycles alone never saw.
COVER_STOP_VISIT_PROBABILITY = 0.3
COVER_OVERSHOOT_M = (-0.03, 0.05)
ENGINE_RPM = 2200.0
#: Rough rod speeds of the reference machine (m/s), used only to keep the boom cycle off
#: its end stops: raising is pump-limited above ~35 % spool, lowering above ~55 %.
_RAISE_M_S, _RAISE_SAT_PCT = 0.129, 35.0
_LOWER_M_S, _LOWER_SAT_PCT = 0.192, 55.0
_STROKE_M = 0.5


def _time_axis(duration_s: float) -> np.ndarray:
    if not duration_s > 0:
        raise ConfigError(f"duration must be positive, got {duration_s:g} s")
    n = int(round(duration_s / SAMPLE_PERIOD_S)) + 1
    return np.arange(n) * SAMPLE_PERIOD_S


def rate_limit(values: np.ndarray, rate_per_s: float, dt_s: float = SAMPLE_PERIOD_S) -> np.ndarray:
    """Slew-rate limit a command (units per second)."""
    out = np.empty_like(values)
    step = rate_per_s * dt_s
    prev = values[0]
    for i, v in enumerate(values):
        prev = prev + min(max(v - prev, -step), step)
        out[i] = prev
    return out


def _oil_temp(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A warm machine: 40-60 degC per run, drifting slowly by a degree or two."""
    base = rng.uniform(40.0, 60.0)
    drift = rng.uniform(-2.0, 2.0)
    return base + drift * t / max(t[-1], 1.0)


def _fill_phases(t: np.ndarray, phases: list[tuple[float, float]]) -> np.ndarray:
    """Piecewise-constant command from (duration_s, level_pct) phases."""
    out = np.zeros_like(t)
    edges = np.cumsum([0.0] + [d for d, _ in phases])
    for (_, level), start, stop in zip(phases, edges[:-1], edges[1:], strict=True):
        out[(t >= start) & (t < stop)] = level
    return out


def boom_phases(
    duration_s: float,
    rng: np.random.Generator,
    stop_visits: float = STOP_VISIT_PROBABILITY,
    overshoot_m: tuple[float, float] | None = None,
) -> list[tuple[float, float]]:
    """Raise / hold / lower / hold, amplitudes 40-100 %, phases 1-4 s.

    The lengths aim the rod at a random target inside the stroke so a long run does not
    sit on an end stop; an operator does the same by eye, and now and then (``stop_visits``
    of the moves) runs into a stop, aiming 5 cm past it or, with ``overshoot_m``, anywhere
    in that range of metres past it (negative: short of it).
    """
    phases: list[tuple[float, float]] = [(rng.uniform(1.0, 2.0), 0.0)]
    pos = 0.1
    total = phases[0][0]
    while total < duration_s:
        for direction in (1.0, -1.0):
            amp = rng.uniform(40.0, 100.0)
            if rng.random() < stop_visits:
                # Now and then the operator drives into the stop and holds the lever a moment.
                # (No draw without a range: a boom cycle's seed gives the same commands.)
                over = 0.05 if overshoot_m is None else rng.uniform(*overshoot_m)
                target = _STROKE_M + over if direction > 0 else -over
            elif direction > 0:
                target = rng.uniform(0.3, 0.45)
            else:
                target = rng.uniform(0.08, 0.2)
            if direction > 0:
                speed = _RAISE_M_S * min(1.0, amp / _RAISE_SAT_PCT)
            else:
                speed = _LOWER_M_S * min(1.0, amp / _LOWER_SAT_PCT)
            move_s = float(np.clip(abs(target - pos) / speed, 1.0, 4.0))
            pos = float(np.clip(pos + direction * speed * move_s, 0.0, _STROKE_M))
            hold_s = rng.uniform(1.0, 4.0)
            phases += [(move_s, direction * amp), (hold_s, 0.0)]
            total += move_s + hold_s
    return phases


def make_cycle(cycle: str, duration_s: float, seed: int) -> Recording:
    """Commands for ``cycle`` (boom, boom-cover, ramp or step) over ``duration_s`` seconds."""
    if cycle not in CYCLES:
        raise ConfigError(f"unknown cycle {cycle!r}; known: {', '.join(CYCLES)}")
    t = _time_axis(duration_s)
    rng = np.random.default_rng(seed)
    if cycle == "boom":
        spool = rate_limit(_fill_phases(t, boom_phases(duration_s, rng)), RATE_LIMIT_PCT_S)
    elif cycle == "boom-cover":
        phases = boom_phases(duration_s, rng, COVER_STOP_VISIT_PROBABILITY, COVER_OVERSHOOT_M)
        spool = rate_limit(_fill_phases(t, phases), RATE_LIMIT_PCT_S)
    elif cycle == "ramp":
        # Slow triangles through the whole spool range: 10 %/s, alternating direction.
        period = 40.0
        phase = (t % period) / period
        spool = 100.0 * np.where(
            phase < 0.25, 4 * phase, np.where(phase < 0.75, 2 - 4 * phase, 4 * phase - 4)
        )
    else:
        phases = []
        total = 0.0
        sign = 1.0
        while total < duration_s:
            hold = rng.uniform(0.5, 2.0)
            phases += [(hold, sign * rng.uniform(20.0, 100.0)), (rng.uniform(0.5, 2.0), 0.0)]
            total += phases[-1][0] + hold
            sign = -sign
        spool = _fill_phases(t, phases)
    columns = {
        "SpoolCmd": spool,
        "PumpDispCmd": np.full_like(t, 100.0),
        "EngineSpeed": np.full_like(t, ENGINE_RPM),
        "OilTemp": _oil_temp(t, rng),
    }
    return Recording(t, columns, source=f"{cycle} cycle, seed {seed}")
