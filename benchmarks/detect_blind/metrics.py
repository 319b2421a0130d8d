"""The figures a detection benchmark states: rates with their bounds, detection, delay."""

from __future__ import annotations

import math
from statistics import median


def poisson_cdf(k: int, lam: float) -> float:
    """P(X <= k) for X ~ Poisson(lam), summed term by term."""
    term = math.exp(-lam)
    total = term
    for i in range(1, k + 1):
        term *= lam / i
        total += term
    return total


def poisson_upper(k: int, confidence: float = 0.95) -> float:
    """One-sided upper bound on a Poisson mean after k events: P(X <= k | bound) = 1 - conf.

    Solved by bisection (0 events: -ln(0.05) = 2.996 at 95 %).
    """
    lo, hi = 0.0, 10.0 + 10.0 * k
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if poisson_cdf(k, mid) > 1.0 - confidence:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


J_WINDOW_S = 30.0  # the monitor's default J window: less judged than that is no verdict


def unjudged(row: dict) -> bool:
    """A log the monitor did not judge: verdict not_judged, or less than one J window judged
    (a log outside the trained range that also tripped a sensor check says sensor_fault)."""
    return row.get("verdict") == "not_judged" or (row.get("judged_s") or 0.0) < J_WINDOW_S


def rate_per_hour(events: int, hours: float) -> dict:
    """Events per hour and the 95 % upper bound of the rate."""
    if hours <= 0:
        return {"events": events, "hours": hours, "per_h": None, "upper95_per_h": None}
    return {
        "events": events,
        "hours": round(hours, 3),
        "per_h": events / hours,
        "upper95_per_h": poisson_upper(events) / hours,
    }


def detection(rows: list[dict]) -> dict:
    """Detection rate, median delay and isolation over fault runs.

    A run is detected when its first alarm comes at or after the onset; an alarm before the
    onset is an early alarm (a false alarm on the run's healthy part), not a detection. A run
    the monitor did not judge (verdict not_judged) counts as not detected, and apart.
    """
    detected = [
        r
        for r in rows
        if r["alarm"] and r["first_alarm_t"] is not None and r["first_alarm_t"] >= r["onset_s"]
    ]
    early = [
        r
        for r in rows
        if r["alarm"] and r["first_alarm_t"] is not None and r["first_alarm_t"] < r["onset_s"]
    ]
    delays = [r["first_alarm_t"] - r["onset_s"] for r in detected]
    named = [r for r in detected if r["fault_named"] == r["fault"]]
    skipped = [r for r in rows if unjudged(r)]
    judged = len(rows) - len(skipped)
    return {
        "runs": len(rows),
        "not_judged": len(skipped),
        "detected": len(detected),
        "rate": len(detected) / len(rows) if rows else None,
        "rate_of_judged": len(detected) / judged if judged else None,
        "early_alarms": len(early),
        "median_delay_s": median(delays) if delays else None,
        "isolated": len(named),
        "isolation": len(named) / len(detected) if detected else None,
        "named": sorted({str(r["fault_named"]) for r in detected}),
    }
