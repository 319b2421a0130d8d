"""What a recording's detection may conclude, and what it may not.

A recording is judged on the samples whose residual entered a full J window while the
monitor was running (state normal or fault, J finite).  The verdict:

* ``fault``: a debounced hydraulic-fault alarm was raised;
* ``sensor_fault``: no alarm, but some sample was a sensor fault (stale or implausible data);
* ``healthy``: neither, and J was judged at least once (each judged J covers a full window
  of N samples of running, in-range, complete data);
* ``not_judged``: no J was ever judged, so the data cannot support "healthy": no commands
  (engine speed never received), a recording shorter than the window, or the engine off,
  warm-up, outside the model's trained range or missing model signals throughout; or the
  model is another machine's (``reference_model``) and would have alarmed: its alarm was
  withheld (``withheld``), since it cannot tell a fault from this machine's difference from
  the model's machine, so neither ``fault`` nor ``healthy`` is supported.

A recording without any EngineSpeed is ``not_judged`` (no commands) even where its samples
are sensor faults because the pump shows a working machine (``opstate.silent_source``): a
log recorded without HYD_Commands supports no verdict, whereas the samples say what the
daemon would have said on the bus.

Data that was never judged is never reported healthy.  Beyond the envelope's oil, where J is
not judged, the flow-continuity statistic F may judge alone (``Statistic.beyond_oil``): it may
raise an alarm there (``fault``), but it looks for piston wear only, so the seconds it judged
(the summary's ``judged_beyond_oil_s``) are not in ``judged_s`` and never make a recording
``healthy``; a ``not_judged`` recording says how long F judged it and that it found none.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from monitor.detection.alarm import State
from monitor.detection.opstate import OpState

VERDICTS = ("fault", "sensor_fault", "healthy", "not_judged")


def judged_mask(states: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Samples judged: the monitor running (normal or fault) with J over a full window."""
    running = (states == State.NORMAL) | (states == State.FAULT)
    return running & np.isfinite(j)


def verdict(
    summary: dict[str, Any],
    states: np.ndarray,
    j: np.ndarray,
    op_state: np.ndarray,
    oor: np.ndarray,
    inputs_ok: np.ndarray,
    engine_rpm: np.ndarray,
    window_n: int,
    period_s: float,
    oor_named: str = "",
) -> tuple[str, float, str | None]:
    """(verdict, judged seconds, why not judged or None) of one recording; ``oor_named``
    says which signal lay outside the trained range, and where (``outofrange.describe``)."""
    judged = judged_mask(states, j)
    judged_s = round(float(judged.sum()) * period_s, 3)
    if summary["alarm"]:
        return "fault", judged_s, None
    no_commands = len(states) > 0 and not np.isfinite(engine_rpm).any()
    if summary["sensor_fault"] and not no_commands:
        return "sensor_fault", judged_s, None
    withheld = summary.get("withheld")
    if withheld:
        return "not_judged", judged_s, withheld["reason"]
    if judged.any():
        return "healthy", judged_s, None
    why = _why(states, op_state, oor, inputs_ok, engine_rpm, window_n, period_s, oor_named)
    alone = summary.get("judged_beyond_oil_s") or 0.0
    if alone > 0:
        why += (
            f"; F alone judged {alone:.1f} s on oil beyond the trained range: no piston wear "
            "(it looks for nothing else)"
        )
    return "not_judged", judged_s, why


def _why(
    states: np.ndarray,
    op_state: np.ndarray,
    oor: np.ndarray,
    inputs_ok: np.ndarray,
    engine_rpm: np.ndarray,
    window_n: int,
    period_s: float,
    oor_named: str = "",
) -> str:
    n = len(states)
    if n and not np.isfinite(engine_rpm).any():
        return "no commands (EngineSpeed never received: HYD_Commands missing)"
    if n < window_n:
        return (
            f"shorter than the J window ({n * period_s:.1f} s of samples, the window is "
            f"{window_n * period_s:.1f} s)"
        )
    reasons = {
        "engine off": np.mean(op_state == OpState.ENGINE_OFF),
        "warm-up": np.mean(op_state == OpState.WARM_UP),
        "outside the trained range": np.mean((op_state == OpState.NORMAL) & (oor >= 0)),
        "model signals missing": np.mean((op_state == OpState.NORMAL) & (oor < 0) & ~inputs_ok),
    }
    named = {"outside the trained range": f" ({oor_named})" if oor_named else ""}
    shares = [
        f"{name} {share:.0%} of the time{named.get(name, '')}"
        for name, share in sorted(reasons.items(), key=lambda kv: -kv[1])
        if share > 0
    ]
    if not shares:
        return f"no full J window ({window_n * period_s:.1f} s) of judged samples"
    return ", ".join(shares) + f"; no full J window ({window_n * period_s:.1f} s) judged"
