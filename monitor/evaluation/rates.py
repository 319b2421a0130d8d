"""Confidence bounds on event rates (false alarms per hour)."""

from __future__ import annotations

from scipy.stats import chi2


def poisson_rate_upper(events: int, hours: float, confidence: float = 0.95) -> float:
    """One-sided upper confidence bound on a Poisson rate, in events per hour.

    The exact (Garwood) bound: the rate ``mu/hours`` such that seeing at most ``events``
    has probability ``1 - confidence``, i.e. ``chi2.ppf(confidence, 2 (events + 1)) / 2``
    events over the observed hours. With no event at 95 % this is about 3.0/hours (rule of
    three).
    """
    if events < 0:
        raise ValueError(f"events must be >= 0, got {events}")
    if not hours > 0:
        raise ValueError(f"hours must be > 0, got {hours}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    return float(chi2.ppf(confidence, 2 * (int(events) + 1)) / 2.0 / hours)
