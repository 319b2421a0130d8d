"""The sim-to-real diagnosis, end to end: prepare, segment, calibrate, test every effect,
decide, and measure how far the gap shrinks.

Verdict rules (thresholds below, chosen on simulated recordings, see the README):
``none`` when the calibrated nominal simulator's held-out residual is within the sensor
noise on every signal; otherwise the best-ranked effect when it removes at least
``EXPLAIN_MIN`` of the held-out gap; otherwise ``unexplained``.  A second effect is named
in ``also`` when the best alone leaves a clear gap that the pair removes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from monitor.errors import NoHydraulicDataError
from monitor.gap import calibrate as cal_mod
from monitor.gap import score as S
from monitor.gap.candidates import KNOBS, Candidate, criterion, fit_candidate, n_params
from monitor.gap.predict import SENSOR_EFFECTS, plant_traces, predict, sense
from monitor.gap.prepare import Prepared, prepare
from monitor.gap.segments import Segment, make_segments, split, spread
from monitor.gap.shrink import boot_gap, boot_reduction, resamples
from monitor.io.recording import Recording
from monitor.sim.effects import Effect
from monitor.sim.machine import MachineParams

#: Seconds of calibration segments the fits simulate per evaluation.
FIT_BUDGET_S = 60.0
#: ``none``: held-out mean squared residual below this multiple of the noise floor on
#: every signal (a perfect simulator sits at 1).
NONE_RATIO = 2.0
#: An effect must remove at least this share of the held-out gap to be named.
EXPLAIN_MIN = 0.5
#: Pairs are tried when the best effect leaves more than this share of the gap ...
PAIR_TRIGGER = 0.25
#: ... with the next candidates that remove at least this much alone ...
PAIR_MIN_SINGLE = 0.05
PAIR_TRIES = 2
#: ... and a pair is kept when it removes this share of what the best leaves.
PAIR_GAIN = 0.5
MIN_SEGMENTS = 3
#: Best single effects refitted together with the tolerances.
REFINE_TOP = 2

Progress = Callable[[str], None]


@dataclass
class Diagnosis:
    """Everything the report needs."""

    prep: Prepared
    segments: list[Segment]
    calibration: list[Segment]
    heldout: list[Segment]
    machine: MachineParams  # tolerance-calibrated
    factors: dict[str, float]
    floor: np.ndarray
    nominal: S.SegmentSums  # held-out, calibrated nominal
    singles: list[Candidate]  # ranked best first
    pairs: list[Candidate]
    sums: dict[str, S.SegmentSums]  # held-out per candidate name
    verdict: str
    also: str | None
    chosen: Candidate | None
    confidence: float
    boot_idx: np.ndarray
    timings_s: dict[str, float] = field(default_factory=dict)


class _Evaluator:
    """Simulations of a fixed set of segments for (tolerance factors, effects) hypotheses.

    Sensor-only effects reuse the plant runs of the same factors (one cached set).
    """

    def __init__(self, prep: Prepared, segments: Sequence[Segment], machine: MachineParams):
        self.prep, self.segments, self.machine = prep, list(segments), machine
        self._base: tuple[tuple, list] | None = None

    def predict(self, factors: dict[str, float], effects: Sequence[Effect]) -> dict:
        m = cal_mod.apply(self.machine, factors)
        if all(e.name in SENSOR_EFFECTS for e in effects):
            key = tuple(sorted(factors.items()))
            if self._base is None or self._base[0] != key:
                self._base = (key, plant_traces(self.prep, self.segments, m, ()))
            return sense(self.prep, self.segments, self._base[1], effects)
        return predict(self.prep, self.segments, m, effects)

    def residual(self, factors: dict[str, float], effects: Sequence[Effect]) -> np.ndarray:
        return S.stacked(self.prep, self.segments, self.predict(factors, effects))

    def sums(self, factors: dict[str, float], effects: Sequence[Effect]) -> S.SegmentSums:
        return S.segment_sums(self.prep, self.segments, self.predict(factors, effects))


def _score(c: Candidate, sums: S.SegmentSums, floor: np.ndarray, gap0: float, n_eff: float):
    c.heldout_mse = sums.mse()
    c.heldout_gap = S.gap(c.heldout_mse, floor)
    c.heldout_reduction = S.reduction(gap0, c.heldout_gap)
    c.criterion = criterion(float(np.mean(c.heldout_mse)), n_eff, n_params(c.effects))


def diagnose(
    rec: Recording,
    machine: MachineParams,
    progress: Progress | None = None,
    effects: Sequence[str] = tuple(KNOBS),
) -> Diagnosis:
    """Diagnose the gap between ``machine``'s simulator and ``rec``."""
    say = progress or (lambda _msg: None)
    clock = time.perf_counter()
    timings: dict[str, float] = {}

    def lap(name: str) -> None:
        timings[name] = time.perf_counter() - clock - sum(timings.values())

    prep = prepare(rec, machine)
    segments = make_segments(prep)
    cal, held = split(segments)
    if len(cal) < MIN_SEGMENTS or len(held) < MIN_SEGMENTS:
        raise NoHydraulicDataError(
            f"{prep.source}: only {len(segments)} usable segments (need {2 * MIN_SEGMENTS}): "
            "too few moves of the boom, or too much missing data"
        )
    fit_segs = spread(cal, FIT_BUDGET_S)
    say(
        f"{len(segments)} segments ({sum(s.quiet for s in segments)} from rest), "
        f"{len(cal)} calibration ({sum(s.duration_s() for s in fit_segs):.0f} s fitted), "
        f"{len(held)} held out; RodPos {'measured' if prep.has_rodpos else 'from flow'}"
    )
    fit_ev = _Evaluator(prep, fit_segs, machine)
    held_ev = _Evaluator(prep, held, machine)
    tol = cal_mod.knobs()

    # 1. Tolerances first.
    factors = fit_candidate([], fit_ev.residual, {}, tol, starts=[({}, ())]).factors
    lap("calibrate")
    say("calibrated " + ", ".join(f"{k} {100 * (v - 1):+.1f} %" for k, v in factors.items()))
    floor = S.noise_floor(prep)
    pred0 = held_ev.predict(factors, ())
    nominal = S.segment_sums(prep, held, pred0)
    gap0 = S.gap(nominal.mse(), floor)
    n_eff = S.effective_n(prep, held, pred0)
    sums: dict[str, S.SegmentSums] = {}

    def scored(c: Candidate) -> Candidate:
        sums[c.name] = held_ev.sums(c.factors, c.effects)
        _score(c, sums[c.name], floor, gap0, n_eff)
        return c

    # 2. Every effect on the calibrated machine, then the best few with the tolerances
    # refitted jointly (a calibration can soak up part of an effect: a deadband looks a
    # little like a weaker valve).
    singles = []
    for i, name in enumerate(effects):
        t0 = time.perf_counter()
        c = scored(fit_candidate([name], fit_ev.residual, factors))
        singles.append(c)
        say(
            f"[{i + 1}/{len(effects)}] {name}: held-out reduction {c.heldout_reduction:+.2f} "
            f"({time.perf_counter() - t0:.1f} s)"
        )
    singles.sort(key=lambda c: c.criterion)
    lap("candidates")
    ratio = nominal.mse() / np.maximum(floor, 1e-12)
    within_noise = bool(np.all(ratio < NONE_RATIO))
    if not within_noise:
        for i, c in enumerate(singles[:REFINE_TOP]):
            starts = [(c.factors, c.effects), ({}, c.effects)]
            kept = sums[c.name]
            r = scored(fit_candidate([c.effects[0].name], fit_ev.residual, factors, tol, starts))
            say(f"refit {r.name} with tolerances: held-out reduction {r.heldout_reduction:+.2f}")
            if r.criterion < c.criterion:
                singles[i] = r
            else:
                sums[c.name] = kept
        singles.sort(key=lambda c: c.criterion)
    lap("refine")

    # 3. Pairs, when the best alone leaves a clear gap.
    pairs: list[Candidate] = []
    best = singles[0]
    if not within_noise and 1.0 - best.heldout_reduction > PAIR_TRIGGER:
        others = [c for c in singles[1:] if c.heldout_reduction >= PAIR_MIN_SINGLE]
        for other in others[:PAIR_TRIES]:
            names = [best.effects[0].name, other.effects[0].name]
            starts = [(best.factors, (*best.effects, *other.effects))]
            c = scored(fit_candidate(names, fit_ev.residual, factors, tol, starts))
            pairs.append(c)
            say(f"pair {c.name}: held-out reduction {c.heldout_reduction:+.2f}")
    lap("pairs")

    idx = resamples(len(held))
    verdict, also, chosen, confidence = _decide(
        within_noise, singles, pairs, sums, nominal, idx, floor
    )
    timings["total"] = time.perf_counter() - clock
    return Diagnosis(
        prep,
        segments,
        cal,
        held,
        cal_mod.apply(machine, factors),
        factors,
        floor,
        nominal,
        singles,
        pairs,
        sums,
        verdict,
        also,
        chosen,
        confidence,
        idx,
        timings,
    )


def _decide(
    within_noise: bool,
    singles: list[Candidate],
    pairs: list[Candidate],
    sums: dict[str, S.SegmentSums],
    nominal: S.SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
) -> tuple[str, str | None, Candidate | None, float]:
    """Verdict, second effect, the chosen candidate and a bootstrap confidence (0..1)."""
    if within_noise:
        # Share of resamples in which every signal stays within the noise band.
        mse_b = nominal.sq[idx].sum(axis=1) / np.maximum(nominal.count[idx].sum(axis=1), 1)
        conf = float(np.mean(np.all(mse_b < NONE_RATIO * floor, axis=1)))
        return "none", None, None, conf
    best = singles[0]
    chosen = best
    also = None
    good_pairs = [
        p
        for p in pairs
        if p.heldout_gap <= (1 - PAIR_GAIN) * best.heldout_gap and p.criterion < best.criterion
    ]
    if good_pairs:
        chosen = min(good_pairs, key=lambda p: p.criterion)
        also = chosen.effects[1].name
    red_b = boot_reduction(nominal, sums[chosen.name], idx, floor)
    if chosen.heldout_reduction < EXPLAIN_MIN:
        return "unexplained", None, None, float(np.mean(red_b < EXPLAIN_MIN))
    # Confidence: the chosen model explains the gap and beats the runner-up in the resample.
    runner = singles[1] if len(singles) > 1 else None
    wins = red_b >= EXPLAIN_MIN
    if runner is not None and chosen is best:
        wins &= boot_gap(sums[best.name], idx, floor) < boot_gap(sums[runner.name], idx, floor)
    return best.effects[0].name, also, chosen, float(np.mean(wins))
