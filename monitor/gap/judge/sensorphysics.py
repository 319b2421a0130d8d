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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import ROD_VEL, Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit import sensorcal
from monitor.gap.fit.candidates import Candidate
from monitor.gap.fit.kinematics import KINEMATIC_TOLERANCE, segment_speeds_per_flow
from monitor.gap.fit.score import SegmentSums, gap, reduction, segment_sums
from monitor.gap.fit.sensorterms import SensorTerm
from monitor.gap.fit.terms import PlantTerm
from monitor.gap.judge import delays
from monitor.gap.judge.decide import EXPLAIN_MIN, SIGNIFICANT, boot_gain, gain_share
from monitor.gap.judge.shrink import boot_reduction
from monitor.gap.judge.suggest import Suggestions
from monitor.sim.effects import CATALOGUE, SENSOR_CAL_SIGNALS, Effect


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


@dataclass
class OwnSignal:
    """A sensor calibration judged on the one signal it reads (held-out part)."""

    signal: str
    reduction: float  # share of that signal's held-out gap the gain and offset remove
    share: float  # bootstrap resamples in which it removes EXPLAIN_MIN of it and gains
    at_bound: bool  # the gain or the offset at the catalogue's range
    #: The delay (ms) the sensor hypothesis's reading of the signal was aligned by before
    #: comparing (``aligned_sums``; 0: not aligned).
    aligned_ms: float = 0.0

    @property
    def named(self) -> bool:
        return self.reduction >= EXPLAIN_MIN and self.share >= SIGNIFICANT and not self.at_bound

    def evidence(self) -> str:
        late = (
            f", with {self.signal} read {self.aligned_ms:.0f} ms late as the recording reads it"
            if self.aligned_ms
            else ""
        )
        return (
            f"a sensor error moves its own signal only: the {self.signal} gain and offset remove "
            f"{100 * self.reduction:.0f} % of {self.signal}'s held-out gap{late} "
            f"({100 * self.share:.0f} % of resamples); the rest of the gap is in signals no "
            f"reading error of {self.signal} reaches"
        )

    def as_dict(self) -> dict:
        return {
            "own_signal_heldout_reduction": round(self.reduction, 4),
            "own_signal_share": round(self.share, 3),
            "own_signal_aligned_ms": round(self.aligned_ms, 1),
            "at_bound": self.at_bound,
            "evidence": self.evidence(),
        }


def _column(sums: SegmentSums, j: int) -> SegmentSums:
    return SegmentSums(sums.sq[:, [j]], sums.count[:, [j]])


def own_signal(
    sensor: Candidate,
    names: tuple[str, ...],
    nominal: SegmentSums,
    after: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
    aligned_ms: float = 0.0,
) -> OwnSignal | None:
    """``sensor`` judged on its own signal's held-out gap (PP, PA, PB or QP; None for
    RodPos, whose offset reaches every signal through the start states it sets, so the
    whole gap judges it, and for a signal not compared).

    A reading error changes what one transducer shows: on a machine whose base dynamics
    differ from the simulator's, the whole gap also holds what no sensor can explain (a
    PP reading 5.8 % high removed a third of the third plant's whole gap, most of PP's).
    Judged on the whole gap it was ``unexplained``; on its signal it is named, and the
    plant terms still get their say (``compare``).  ``nominal`` and ``after``: the held-out
    sums, each with the signal aligned by its own delay (``aligned_sums``), the hypothesis's
    ``aligned_ms``."""
    effect = sensor.effects[0]
    signal = effect.labels["signal"]
    if signal == "RodPos" or signal not in names:
        return None
    j = names.index(signal)
    before_j, after_j, floor_j = _column(nominal, j), _column(after, j), floor[[j]]
    red = reduction(gap(before_j.mse(), floor_j), gap(after_j.mse(), floor_j))
    red_b = boot_reduction(before_j, after_j, idx, floor_j)
    gain_b = boot_gain(before_j, after_j, idx, floor_j)
    share = float(np.mean((red_b >= EXPLAIN_MIN) & (gain_b > 0)))
    g, o = CATALOGUE[sensorcal.NAME].param("gain"), SENSOR_CAL_SIGNALS[signal].max_offset
    at_bound = (
        min(effect.params["gain"] - g.low, g.high - effect.params["gain"]) < 1e-3
        or abs(effect.params["offset"]) > o - 1e-3
    )
    return OwnSignal(signal, red, share, at_bound, aligned_ms)


@dataclass
class RodKinematics:
    """A RodPos calibration judged by flow continuity (``rod_kinematics``): the JSON's
    ``sensor_check`` beside ``OwnSignal``'s for the other readings."""

    ratio: float  # measured rod speed per measured pump flow over the simulator's
    after: float  # the same, the rod read through the hypothesis's gain
    share: float  # resamples: above 1 + KINEMATIC_TOLERANCE, and within it through the gain
    reduction: float  # of the whole held-out gap, by the hypothesis
    at_bound: bool
    gain: float
    signal: str = "RodPos"

    @property
    def named(self) -> bool:
        return self.reduction >= EXPLAIN_MIN and self.share >= SIGNIFICANT and not self.at_bound

    def evidence(self) -> str:
        return (
            f"flow continuity: extending, the rod reads {100 * (self.ratio - 1):.1f} % faster "
            "per litre of measured pump flow than the cap area lets it move (no leak or load "
            f"does that; {100 * self.share:.0f} % of resamples), and a RodPos gain of "
            f"{self.gain:.3f} brings it to {100 * (self.after - 1):+.1f} % and removes "
            f"{100 * self.reduction:.0f} % of the held-out gap"
        )

    def as_dict(self) -> dict:
        return {
            "signal": self.signal,
            "kinematic_ratio": round(self.ratio, 4),
            "kinematic_ratio_through_gain": round(self.after, 4),
            "kinematic_share": round(self.share, 3),
            "heldout_reduction": round(self.reduction, 4),
            "at_bound": self.at_bound,
            "evidence": self.evidence(),
        }


def rod_kinematics(
    sensor: Candidate,
    prep: Prepared,
    segments: Sequence[Segment],
    pred: dict[str, np.ndarray],
    idx: np.ndarray,
) -> RodKinematics | None:
    """A RodPos gain above 1 judged by flow continuity, not by the residual's bootstrap:
    extending, the cap side takes the pump's flow less any leak, so no physical effect moves
    the rod faster per measured litre than the simulator's cap area does; a stroke sensor
    reading fast does.  Named when the recording's rod speed per pump flow (held-out
    extension rows) is above the simulator's by more than ``KINEMATIC_TOLERANCE`` and the
    gain brings it within that, both in ``SIGNIFICANT`` of the resamples of the segments,
    and the hypothesis removes ``EXPLAIN_MIN`` of the held-out gap.  The third plant's
    s730896_57 (gain 1.137): the rod 13.7 % fast, the fitted gain 1.138 removed 59 % of
    the gap, carried by a few segments whose starts the rod sets (35 % of resamples).  A
    rod read slow is what any leak makes (None: the whole gap judges it), and so is a
    RodPos offset, which reaches every signal through the start states."""
    effect = sensor.effects[0]
    if effect.params["gain"] <= 1.0 + KINEMATIC_TOLERANCE or ROD_VEL not in pred:
        return None
    meas, sim = segment_speeds_per_flow(prep, segments, pred, None)
    through, _ = segment_speeds_per_flow(prep, segments, pred, effect)
    if sim.sum() <= 0.0:
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        before_b = meas[idx].sum(axis=1) / sim[idx].sum(axis=1)
        after_b = through[idx].sum(axis=1) / sim[idx].sum(axis=1)
    tol = KINEMATIC_TOLERANCE
    share = float(np.mean((before_b > 1.0 + tol) & (np.abs(np.log(after_b)) <= tol)))
    g = CATALOGUE[sensorcal.NAME].param("gain")
    return RodKinematics(
        ratio=float(meas.sum() / sim.sum()),
        after=float(through.sum() / sim.sum()),
        share=share,
        reduction=float(sensor.heldout_reduction),
        at_bound=min(effect.params["gain"] - g.low, g.high - effect.params["gain"]) < 1e-3,
        gain=float(effect.params["gain"]),
    )


def aligned_sums(
    prep: Prepared,
    segments: Sequence[Segment],
    pred: dict[str, np.ndarray],
    signal: str,
) -> tuple[SegmentSums, float]:
    """The held-out sums of ``pred`` with ``signal`` read as late as fits the recording best
    (least squares, 0-60 ms: ``delays.fitted_ms``), and that delay (ms).

    A late reading hides its calibration: on the third plant PA read 14-20 ms late, and a
    PA gain of 1.063 with a -9.5 bar offset (fitted 1.027, -4.2 bar) removed 49 % of PA's
    held-out gap as it arrived, the rest its timing; each of the calibrated simulator and
    the sensor hypothesis read at its own best delay, 63 % in every resample.  Each gets
    the same one delay to fit, so the gain and offset are judged on what they add to it."""
    ms = delays.fitted_ms(prep, segments, pred, [signal])[signal]
    term = SensorTerm("sensor_delay", signal, ms)
    return segment_sums(prep, segments, term.apply(prep, segments, pred) if ms else pred), ms


def rod_evidence(effect: Effect, prep: Prepared) -> str:
    """What fixes a RodPos gain and offset, in words: the rod's speed per pump flow (the
    gain) and the readings at its end stops (the offset), which set the segments' starts."""
    gain, offset = effect.params["gain"], effect.params["offset"]
    top = gain * prep.stroke_mm + offset
    clip = (
        "; the sensor clips at 0: a rod read 0 rests on its bottom stop, or hangs above it "
        "where its chambers hold the load"
        if offset < 0 and prep.rod_clips
        else ""
    )
    return (
        f"a stroke sensor error moves the reading, not the rod: the gain ({gain:.3f}) from "
        f"the rod's speed per pump flow, the offset ({offset:+.1f} mm) from where the rod "
        f"rests on its stops, the top one read at {top:.0f} mm of a {prep.stroke_mm:.0f} mm "
        f"stroke{clip}"
    )
