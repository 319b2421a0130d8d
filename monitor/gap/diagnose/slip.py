"""A pump leakage within a healthy pump's slip is ``none`` (``judge/pumpslip.py``).

Run on ``unexplained`` verdicts whose ``oil_viscosity`` single leaks mainly from the pump
(named pump leakage of wear or undecided cause by ``cause.py``, or below the naming bar):
the leak at the recording's oil temperature against the slip of a pump at 95 % volumetric
efficiency, and the simulator with it against what a healthy machine leaves.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from monitor.gap.diagnose import cause as cause_mod
from monitor.gap.diagnose.records import Calibrated, Paired, Parts, Scores
from monitor.gap.diagnose.verdict import Judged
from monitor.gap.fit.candidates import Candidate
from monitor.gap.judge import pumpslip
from monitor.gap.judge.decide import Decision
from monitor.sim.pack import viscosity_cst

Progress = Callable[[str], None]

PUMP = "pump_leak_lpm_per_100bar"


def recorded_leak(c: Candidate, chk: cause_mod.LeakCause | None, parts: Parts) -> float:
    """The pump leak (L/min per 100 bar) at the recording's oil temperature, as the
    suggestion gives it (``cause.suggestion_entry``): the constant leak where the oil
    temperature said wear, else the better-scoring law's at the mean of the oil
    temperature's 5th and 95th percentiles (without a cause check, below the naming bar:
    the viscous law's there)."""
    if chk is not None:
        return float(cause_mod.suggestion_entry(chk)["coefficient"])
    p = c.effects[0].params
    temps = cause_mod.oil_range_c(parts)
    if temps is None:
        return float(p[PUMP])
    nu = viscosity_cst(np.asarray([np.mean(temps)]), p["nu40_cst"], p["nu100_cst"])
    return float(p[PUMP] * p["nu40_cst"] / nu[0])


def check_slip(
    parts: Parts, cal: Calibrated, scores: Scores, paired: Paired, judged: Judged, say: Progress
) -> Judged:
    """Stage 6c: an ``unexplained`` pump leakage within a healthy pump's slip is ``none``."""
    d = judged.decision
    if d.verdict != "unexplained":
        return judged
    c = next((s for s in scores.singles if s.name == cause_mod.NAME), None)
    if c is None or cause_mod.main_path(c) != PUMP or c.name not in paired.smooth:
        return judged
    m = cal.fit_machine
    rest = pumpslip.rest_is_none(
        paired.sums[c.name], paired.smooth[c.name], paired.boot_idx, cal.floor
    )
    slip = pumpslip.PumpSlip(
        leak_lpm_per_100bar=recorded_leak(c, judged.cause, parts),
        healthy_max_lpm_per_100bar=pumpslip.healthy_max_lpm_per_100bar(m),
        full_flow_lpm=pumpslip.full_flow_lpm(m),
        rated_bar=pumpslip.rated_bar(m),
        rest_none=rest,
    )
    say(f"pump slip: {slip.evidence()}")
    if slip.healthy:
        d = Decision("none", None, None, float(slip.rest_none or 0.0))
    return replace(judged, decision=d, slip=slip.as_dict())
