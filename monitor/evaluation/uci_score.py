"""Scoring of ``monitor eval-uci``: the contract's rates on --test and the held-out score on
--train that chooses the preset and window."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from monitor.evaluation.uci_bias import CycleRule
from monitor.evaluation.uci_data import RigCycles
from monitor.evaluation.uci_presets import DETECTION_KEYS
from monitor.model.threshold import ThresholdRule


def _rate(mask: np.ndarray, alarms: np.ndarray) -> float | None:
    return float(alarms[mask].mean()) if mask.any() else None


def score(rc: RigCycles, alarms: np.ndarray) -> dict[str, Any]:
    """The contract's rates plus breakdowns by cooler state and stable flag."""
    healthy = rc.healthy
    out: dict[str, Any] = {
        "healthy_false_alarm_rate": _rate(healthy, alarms),
        "detection": {f"{c}={v}": _rate(rc.profile[c] == v, alarms) for c, v in DETECTION_KEYS},
        "any_fault_detection": _rate(~healthy, alarms),
        "counts": {
            "cycles": len(rc),
            "healthy": int(healthy.sum()),
            "alarmed": int(alarms.sum()),
            **{f"{c}={v}": int((rc.profile[c] == v).sum()) for c, v in DETECTION_KEYS},
        },
    }
    by: dict[str, Any] = {}
    for cond, values in (("cooler", (100, 20, 3)), ("stable", (0, 1))):
        for v in values:
            m = rc.profile[cond] == v
            by[f"{cond}={v}"] = {
                "cycles": int(m.sum()),
                "healthy_false_alarm_rate": _rate(m & healthy, alarms),
                "any_fault_detection": _rate(m & ~healthy, alarms),
            }
    out["by_condition"] = by
    return out


def selection(
    jmax: np.ndarray,
    means: np.ndarray | None,
    rc: RigCycles,
    j0_idx: np.ndarray,
    rule: ThresholdRule,
) -> dict[str, Any]:
    """Held-out score on --train: detection on its faulty cycles (never used for patterns or
    J0) and a two-fold false-alarm rate on the J0 cycles (thresholds from one half, alarms
    counted on the other).  Youden's index = detection - false-alarm rate."""
    faulty = ~rc.healthy
    alarms = CycleRule.fit(jmax, means, j0_idx, rule).alarms(jmax, means)
    det = float(alarms[faulty].mean()) if faulty.any() else math.nan
    halves = (j0_idx[0::2], j0_idx[1::2])
    fa = []
    if len(halves[1]):
        for a, b in (halves, halves[::-1]):
            on_b = CycleRule.fit(jmax, means, a, rule).alarms(jmax, means)[b]
            fa.append(float(on_b.mean()))
    far = float(np.mean(fa)) if fa else math.nan
    return {
        "fault_cycles": int(faulty.sum()),
        "detection": det,
        "cv_false_alarm_rate": far,
        "score": det - (far if fa else 0.0),
    }
