"""The staleness rules of a row's values, one function each for the live sampler and the bulk
path: when a value is fresh, and when a signal not seen yet stops holding the first rows back
(warming)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from monitor.signals import SAMPLE_PERIOD_S

#: A signal whose last frame came at most this many of its own cycle times before the
#: bus's newest frame was on schedule when the bus went quiet.
ON_SCHEDULE_CYCLES = 1.5


def fresh(
    inst: Any, last_t: Any, newest_t: Any, resumed_t: Any, stale_s: Any, on_schedule_s: Any
) -> Any:
    """Whether a signal's last value (sampler time ``last_t``) is fresh at instant ``inst``
    (all s, numpy broadcasting).  ``newest_t`` is the newest frame of any message visible
    at ``inst``.

    A signal is stale once its value is older than ``stale_s``, counted from the end of the
    last outage (``resumed_t``) when that is later.  A signal that was on schedule when the
    whole bus went quiet (its last frame within ``on_schedule_s`` of ``newest_t``) counts
    from ``newest_t``: every such signal goes stale on the same row, so a silent bus reads
    as silence, never as one sensor failing a fraction of a millisecond before the others
    (the order of a burst's frames is the sender's, not the sensors').  On a bus that is
    not silent the rule is the plain one: a signal only counts from ``newest_t`` while its
    own value is younger than ``on_schedule_s``, and so fresh anyway."""
    seen_t = np.where(newest_t - last_t <= on_schedule_s, newest_t, last_t)
    return inst - np.maximum(seen_t, resumed_t) <= stale_s


def deadline_row(stale_s: float, period_s: float = SAMPLE_PERIOD_S) -> int:
    """First instant k whose time ``k * period_s`` is past ``stale_s``: a signal not seen by
    then has missed its own cycle time by the margin, and is stale rather than warming."""
    k = math.floor(stale_s / period_s) + 1
    while k > 0 and (k - 1) * period_s > stale_s:  # the products the rows use decide
        k -= 1
    while k * period_s <= stale_s:
        k += 1
    return k


def warm_row(first_seen_rows: Iterable[float], deadline_rows: Iterable[int]) -> int:
    """First row that is not warming: by it every required signal has been seen (its first
    frame visible from row ``first_seen_rows[i]``, inf if not yet) or is past its deadline
    (``deadline_rows[i]``, from ``deadline_row``)."""
    return int(
        max((min(s, d) for s, d in zip(first_seen_rows, deadline_rows, strict=True)), default=0)
    )
