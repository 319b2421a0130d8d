"""How well this recording tells the look-alikes apart: friction from viscous friction,
a sensor lag from hose compliance and from the volumes, air from hoses.

Each effect's *signature* is what its fitted value changes in the calibration part's
normalised residual (the effect as its single fit found it, on the calibrated simulator);
a tolerance's is what a quarter of its band changes.  Two signatures that point the same
way (cosine near +-1) can stand in for each other to first order: a fit of one soaks up the
other, and a tolerance at its bound may be an effect.  ``unique_share`` = 1 - cos^2 is the
share of one signature the other cannot reproduce at any size: near 0, this recording
cannot separate the pair (which recording would: ``judge/mechanism.py``); the verdict's
evidence then has to come from a signature only one of them has (the engine's ripple
read late, a leak against the oil temperature).

Cost: one simulation of the fit segments per signature (eight, and one more for each
tolerance the calibration left at its bound and each effect it can stand in for outside
``PAIRS``: mass, valve gain, gravity load; valve deadband, load variation; a sensor lag's
reuses the calibrated plant run).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from monitor.gap.diagnose.records import Calibrated, Scores
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit.candidates import CONFOUNDED, Candidate

#: The pairs measured (an effect, or a tolerance by its ``calibrate`` name).
PAIRS: tuple[tuple[str, str], ...] = (
    ("cylinder_friction", "viscous_friction"),
    ("oil_viscosity", "viscous_friction"),
    ("sensor_lag", "hose_compliance"),
    ("sensor_lag", "volumes"),
    ("hose_compliance", "volumes"),
    ("entrained_air", "hose_compliance"),
)
#: A tolerance's signature: this share of its band, away from the nearer bound.
TOLERANCE_STEP = 0.25


def measured_pairs(factors: dict[str, float]) -> list[tuple[str, str]]:
    """``PAIRS``, and each tolerance the calibration left at its bound with every effect
    it can stand in for (``CONFOUNDED``): a bound is evidence only as far as the recording
    can tell the two apart (``report/bounds.py`` quotes the cosine)."""
    out = list(PAIRS)
    for effect, tols in CONFOUNDED.items():
        for t in tols:
            at_bound = cal_mod.bound_side(t, factors.get(t, 1.0)) != 0
            if at_bound and (effect, t) not in out:
                out.append((effect, t))
    return out


def _signature(name: str, cal: Calibrated, scores: Scores, base: np.ndarray) -> np.ndarray | None:
    factors = scores.baseline.factors
    fit_ev = cal.readings.fit(None)
    if name in cal_mod.BY_NAME:
        band = cal_mod.BY_NAME[name].band
        f0 = factors.get(name, 1.0)
        step = TOLERANCE_STEP * band * (1.0 if f0 <= 1.0 else -1.0)
        return fit_ev.residual({**factors, name: f0 + step}, ()) - base
    c = _single(scores.singles, name)
    if c is None or c.prep is not None:  # a single that rereads the recording: not comparable
        return None
    return fit_ev.residual(factors, c.effects) - base


def _single(singles: Sequence[Candidate], name: str) -> Candidate | None:
    return next((c for c in singles if len(c.effects) == 1 and c.effects[0].name == name), None)


def measure(cal: Calibrated, scores: Scores) -> list[dict]:
    """The JSON's ``identifiability``: per pair, the cosine of the two signatures, the
    share of each that the other cannot reproduce, and each signature's size (RMS, in
    normalised units, against the calibrated simulator's residual RMS)."""
    fit_ev = cal.readings.fit(None)
    base = fit_ev.residual(scores.baseline.factors, ())
    base_rms = float(np.sqrt(np.mean(base**2))) or 1.0
    pairs = measured_pairs(scores.baseline.factors)
    names = sorted({n for pair in pairs for n in pair})
    sigs = {n: _signature(n, cal, scores, base) for n in names}
    out = []
    for a, b in pairs:
        sa, sb = sigs[a], sigs[b]
        if sa is None or sb is None:
            continue
        na, nb = float(np.linalg.norm(sa)), float(np.linalg.norm(sb))
        cos = float(sa @ sb / (na * nb)) if na > 0 and nb > 0 else 0.0
        out.append(
            {
                "pair": [a, b],
                "cosine": round(cos, 3),
                "unique_share": round(1.0 - cos**2, 3),
                "size": {
                    a: round(na / np.sqrt(sa.size) / base_rms, 4),
                    b: round(nb / np.sqrt(sb.size) / base_rms, 4),
                },
            }
        )
    return out
