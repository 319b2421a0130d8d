"""The fault plan's vocabulary for `monitor eval-sim`: onset kinds and default severities
(light to import, so the command line can offer them)."""

from __future__ import annotations

ONSETS = ("abrupt", "gradual")  # a fault at full severity at once, or ramped in over 30 s
DEFAULT_SEVERITIES = tuple(round(0.1 * k, 1) for k in range(1, 11))  # 0.1 .. 1.0
#: Test seed sets lie this far apart (a plan's seeds stay below 1.4e6 within a set); set 0 is
#: the development set, the others are for blind results.
SEED_SET_STRIDE = 10_000_000
#: The largest set whose seeds all stay below 2**32 (a plan's seeds reach 1.3e6 within a set):
#: the range every numpy generator, legacy ones included, takes as a seed.
MAX_SEED_SET = 429
#: Simulated faulty runs per fault and severity from which a preset trained afresh learns its
#: fault signatures (as the shipped model).
ISOLATION_RUNS = 8
