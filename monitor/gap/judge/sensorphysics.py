"""A ``sensor_calibration`` verdict checked against the physics it cannot produce.

A reading error changes one signal and leaves the others' physics alone.  A plant change
that shows mostly in one signal does not: a pump compensator set 40 bar low reads like a PP
offset wherever the pump sits at its compensator pressure, but it also drives less flow
through the valve, so QP and the rod's speed change with it; an A->tank leak shows in PA
and in the rod's sinking at holds alike.  So before a sensor error is named, the
correction library's plant terms (``suggest.py``: pump and valve settings, leakages, rod
forces) are fitted to the same calibration part and scored on the same held-out segments.
If a plant term removes more of the held-out gap, over every signal, than the sensor's
gain and offset, then what the sensor hypothesis leaves in the other signals is physics
that moved with it: the sensor is not the cause, and the verdict is ``unexplained`` with
that term as the lead.  A real reading error keeps its verdict, because no plant term can
move its one signal without moving the others, which the recording does not show.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.fit.candidates import Candidate
from monitor.gap.fit.score import SegmentSums
from monitor.gap.fit.terms import PlantTerm
from monitor.gap.judge.decide import gain_share
from monitor.gap.judge.suggest import Suggestions


@dataclass
class Comparison:
    """The sensor calibration against the library's best plant term, on the held-out part."""

    signal: str  # the sensor the calibration blames
    sensor_reduction: float  # held-out reduction of the sensor calibration (0..1)
    term: str  # the plant term's kind and what it acts on, e.g. "pump_setting compensator"
    term_reduction: float  # held-out reduction of that term alone
    plant_share: float  # share of bootstrap resamples in which the term has the smaller gap
    sensor_named: bool  # False: the plant term explains more, the sensor is not the cause

    def as_dict(self) -> dict:
        return {
            "signal": self.signal,
            "sensor_heldout_reduction": round(self.sensor_reduction, 4),
            "term": self.term,
            "term_heldout_reduction": round(self.term_reduction, 4),
            "plant_wins_share": round(self.plant_share, 3),
            "sensor_named": self.sensor_named,
        }


def compare(
    sensor: Candidate,
    sensor_sums: SegmentSums,
    lead: Suggestions,
    idx: np.ndarray,
    floor: np.ndarray,
) -> Comparison | None:
    """``sensor`` (held-out sums ``sensor_sums``) against the library's best plant
    term on the same held-out segments and gap measure.  The sensor is not named when the
    library's first suggestion is that plant term and it has the smaller held-out gap.
    None when the library scored no plant term."""
    plant = [f for f in lead.singles if isinstance(f.terms[0], PlantTerm) and f.sums is not None]
    if not plant:
        return None
    best = plant[0]
    term = best.terms[0]
    assert isinstance(term, PlantTerm) and best.sums is not None
    first = bool(lead.ranked) and lead.singles[0] is best
    return Comparison(
        sensor.effects[0].labels["signal"],
        float(sensor.heldout_reduction),
        f"{term.kind} {term.signal}",
        float(best.heldout_reduction),
        gain_share(sensor_sums, best.sums, idx, floor),
        not (first and best.heldout_gap < sensor.heldout_gap),
    )
