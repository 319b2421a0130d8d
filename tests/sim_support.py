"""Helpers for the simulator tests: hand-made command profiles."""

from __future__ import annotations

import numpy as np

from monitor.io.recording import Recording


def commands(
    profile: list[tuple[float, float, float]],
    duration_s: float,
    disp_pct: float = 100.0,
    speed_rpm: float = 2200.0,
    oil_temp_c: float = 50.0,
) -> Recording:
    """SpoolCmd piecewise constant: (start_s, stop_s, level_pct) phases, 0 elsewhere."""
    t = np.arange(int(round(duration_s / 0.01)) + 1) * 0.01
    spool = np.zeros_like(t)
    for start, stop, level in profile:
        spool[(t >= start - 1e-9) & (t < stop - 1e-9)] = level
    return Recording(
        t,
        {
            "SpoolCmd": spool,
            "PumpDispCmd": np.full_like(t, disp_pct),
            "EngineSpeed": np.full_like(t, speed_rpm),
            "OilTemp": np.full_like(t, oil_temp_c),
        },
        source="test profile",
    )


def at(rec: Recording, name: str, t_s: float) -> float:
    return float(rec[name][int(round(t_s / 0.01))])
