"""A recording of held commands for the valve's held-flow reads (``judge/heldflow.py``,
``judge/flowforce.py``): each level held 1.4 s out of a centred spool, raising then
lowering, over the simulator's step cycle (its pump and engine columns)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from monitor.io.recording import Recording
from monitor.sim.cycles import make_cycle


def held_levels(levels: Sequence[float], seconds: float = 60.0, name: str = "stairs") -> Recording:
    """``levels`` (% stroke) held in turn, each once raising and once lowering."""
    cmd = make_cycle("step", seconds, 5)
    spool = np.zeros_like(cmd.t)
    period = 2.2
    for i in range(int(seconds / period) - 1):
        level = levels[(i // 2) % len(levels)] * (1 if i % 2 == 0 else -1)
        spool[(cmd.t >= i * period + 0.8) & (cmd.t < (i + 1) * period)] = level
    return Recording(cmd.t, {**cmd.columns, "SpoolCmd": spool}, name)
