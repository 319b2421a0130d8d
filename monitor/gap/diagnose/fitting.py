"""The diagnosis's fitting stages: the recording split into parts, the tolerances
calibrated, every effect fitted and scored, the best refitted with the tolerances, pairs.

Each stage takes the records of the stages before it and returns a new frozen record
(``records.py``)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace

from monitor.errors import NoHydraulicDataError
from monitor.gap.data.prepare import Prepared, prepare
from monitor.gap.data.reread import without_arrivals_of
from monitor.gap.data.segments import make_segments, split, spread
from monitor.gap.diagnose.evaluate import Evaluator, MemberJudge, Readings, Sums, score
from monitor.gap.diagnose.records import Baseline, Calibrated, Paired, Parts, Scores
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit import score as S
from monitor.gap.fit import sensorcal
from monitor.gap.fit.candidates import CONFOUNDED, Candidate, Member, default_member, fit_candidate
from monitor.gap.fit.families import fit_family
from monitor.gap.judge import basemis, flowforce, heldflow
from monitor.gap.judge.decide import pair_plan, within_noise
from monitor.gap.judge.shrink import resamples
from monitor.io.recording import Recording
from monitor.sim.machine import BAR, MachineParams

Progress = Callable[[str], None]

#: Seconds of calibration segments the fits simulate per evaluation.
FIT_BUDGET_S = 30.0
#: The fits integrate with this multiple of the configured RK4 step (200 us: 333 us, still
#: 30 steps per 100 Hz sample and a 1 kHz record).  At the stiffest corner of the tolerance
#: bands (volumes and mass -15 %) that departs from the configured step by 0.014 of the
#: pressure sensors' noise variance (500 us: 0.84, 1 ms: several times the noise), so the
#: fits' optimum stays put.
FIT_STEP_FACTOR = 5.0 / 3.0
#: The held-out scores' step, the same multiple: a held-out run of every candidate at the
#: configured step was a third of a diagnosis's CPU, and the departure (0.014 of the noise
#: variance at the stiffest corner) is a small share of the bootstrap spread of any gap the
#: verdict weighs.  The report's whole-recording simulations keep the configured step.
HELDOUT_STEP_FACTOR = FIT_STEP_FACTOR
#: Trust-region iterations of the tolerance calibration (five factors that trade off
#: against each other converge slowly: six iterations left a +-5 % machine 20x the noise).
CAL_ITERATIONS = 15
MIN_SEGMENTS = 3
#: Best single effects refitted together with the tolerances.
REFINE_TOP = 2
#: Local fits of an effect fitted with the tolerance it trades off against (from the best
#: starts, the calibrated and the nominal tolerance among them): friction fitted after a
#: calibration that pushed viscous friction to its bound ended in a worse local minimum.
CONFOUNDED_LOCAL_STARTS = 2
#: The effects that get those two local fits.  For the others the second never ended
#: materially lower on the held-out part (it once ended far worse there) and cost 6-9 %
#: of a diagnosis's CPU (docs/benchmarks.md, "every family's second local fit").
TWO_LOCAL_FITS = ("cylinder_friction",)


def split_recording(rec: Recording, machine: MachineParams, say: Progress) -> Parts:
    """Stage 1: the recording prepared, cut into segments, split into calibration and
    held-out parts (too few of either: ``NoHydraulicDataError``)."""
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
    return Parts(prep=prep, segments=segments, calibration=cal, heldout=held, fitted=fit_segs)


def valve_law(parts: Parts, machine: MachineParams, say: Progress) -> MachineParams:
    """Stage 1b: the simulator's valve closed by flow forces where the held flows show it
    (``flowforce.read``: levels held against drops far apart, the opening falling with the
    drop, read jointly with an overlap so that an overlap is not taken for it), at the
    flow forces they read; elsewhere ``machine`` as configured.  Read, not calibrated: with
    a compensated pump the small commands meet the high drops, and a calibration fitting
    both takes an overlap up as flow forces (the fifth plant's deadbands of 14-16 %:
    flow forces calibrated at 0.008-0.015/bar, read at 0.004)."""
    read = flowforce.read(parts.prep, parts.segments, machine)
    if read is None or not read.shown or machine.valve.flow_force > 0.0:
        return machine
    say(f"valve: {flowforce.line(read.as_dict())}")
    return machine.with_changes(flow_force=read.k_per_bar / BAR)


def make_baseline(
    prep: Prepared, parts: Parts, held_ev: Evaluator, floor, tol_fit: Candidate
) -> Baseline:
    """The calibrated simulator (``tol_fit``'s tolerances) on the held-out part."""
    held = parts.heldout
    pred0 = held_ev.predict(tol_fit.factors, ())
    nominal = S.segment_sums(prep, held, pred0)
    return Baseline(
        cal=tol_fit,
        factors=tol_fit.factors,
        pred0=pred0,
        nominal=nominal,
        smooth_nominal=basemis.smoothed_sums(prep, held, pred0),
        gap0=S.gap(nominal.mse(), floor),
        n_eff=S.effective_n(prep, held, pred0),
    )


def calibrate_tolerances(parts: Parts, machine: MachineParams, say: Progress) -> Calibrated:
    """Stage 2: the tolerances fitted on the calibration part, from the nominal values.
    Without RodPos, the arrivals the rod path read through a first QP calibration finds are
    left out for every candidate, before any is scored (``reread.py``: fairness)."""
    fit_machine = machine.with_changes(step_s=machine.solver.step_s * FIT_STEP_FACTOR)
    held_machine = machine.with_changes(step_s=machine.solver.step_s * HELDOUT_STEP_FACTOR)
    prep, fit_segs = parts.prep, parts.fitted
    readings = Readings(prep, (fit_segs, fit_machine), (parts.heldout, held_machine), machine)
    fit_ev = readings.fit(None)
    # The metering curve's shape is a tolerance only where the held flows show notches and
    # rule out an overlap (``heldflow.metering``): elsewhere notches would take an overlap
    # up (a smooth-cornered 6-14 % one read as notches over 20-29 % of the stroke).
    curve = heldflow.metering(prep, parts.segments, machine)
    tol = cal_mod.knobs(shapes=curve is not None and curve.progressive)
    tol_fit = fit_candidate([], fit_ev.residual, {}, tol, [({}, ())], CAL_ITERATIONS)
    guess = sensorcal.fit_signal(prep, fit_segs, fit_ev.predict(tol_fit.factors, ()), "QP")
    common = prep if guess is None else without_arrivals_of(prep, guess, machine)
    if common is not prep:
        prep = common
        readings = Readings(prep, (fit_segs, fit_machine), (parts.heldout, held_machine), machine)
    floor = S.noise_floor(prep)
    base = make_baseline(prep, parts, readings.held(None), floor, tol_fit)
    say("calibrated " + percent(base.factors))
    return Calibrated(
        prep=prep,
        readings=readings,
        baseline=base,
        floor=floor,
        fit_machine=fit_machine,
        held_machine=held_machine,
    )


def held_sums(c: Candidate, cal: Calibrated, base: Baseline, kept: Sums | None = None) -> Sums:
    """``c`` scored on the held-out part as it reads the recording (same samples); its
    whole and smoothed sums (``kept``: already simulated by its family's judge)."""
    both = kept if kept is not None else cal.readings.held(c.prep).both_sums(c.factors, c.effects)
    score(c, both[0], cal.floor, base.gap0, base.n_eff)
    return both


def _fit_single(name: str, parts: Parts, cal: Calibrated) -> tuple[Candidate, Sums]:
    """One effect fitted on the calibrated machine (with the tolerances it trades off
    against refitted) and scored on the held-out part."""
    base, fit_ev = cal.baseline, cal.readings.fit(None)
    if name == sensorcal.NAME:
        c = sensorcal.fit_candidate(
            cal.prep, parts.fitted, fit_ev.predict, base.factors, cal.readings.reread_for
        )
        return c, held_sums(c, cal, base)
    free = [k for k in cal_mod.knobs(base.factors) if k.name in CONFOUNDED.get(name, ())]
    local = CONFOUNDED_LOCAL_STARTS if free and name in TWO_LOCAL_FITS else 1
    judge = MemberJudge(cal.readings.held(None), cal.floor, base.gap0, base.n_eff)
    c = fit_family(name, fit_ev.residual, base.factors, free, local, judge, base.cal.fit_cost)
    return c, held_sums(c, cal, base, judge.kept.get(id(c)))


def fit_singles(parts: Parts, cal: Calibrated, effects: Sequence[str], say: Progress) -> Scores:
    """Stage 3: every effect on the calibrated machine, ranked by its held-out criterion."""
    singles: list[Candidate] = []
    sums: dict[str, S.SegmentSums] = {}
    smooth: dict[str, S.SegmentSums] = {}
    for i, name in enumerate(effects):
        t0 = time.perf_counter()
        c, both = _fit_single(name, parts, cal)
        sums[c.name], smooth[c.name] = both
        singles.append(c)
        say(
            f"[{i + 1}/{len(effects)}] {name}: held-out reduction {c.heldout_reduction:+.2f} "
            f"({time.perf_counter() - t0:.1f} s)"
        )
    singles.sort(key=lambda c: c.criterion)
    return Scores(singles=singles, sums=sums, smooth=smooth, baseline=cal.baseline)


def _refit(c: Candidate, parts: Parts, cal: Calibrated, base: Baseline) -> Candidate:
    """``c`` refitted with all the tolerances jointly (unscored)."""
    tol = cal_mod.knobs(base.factors)
    if c.name == sensorcal.NAME:
        own = c.prep if c.prep is not None else cal.prep
        predict = cal.readings.fit(c.prep).predict
        return sensorcal.refit_with_tolerances(own, parts.fitted, predict, c, tol)
    starts = [(c.factors, c.effects), ({}, c.effects)]
    residual = cal.readings.fit(None).residual
    members = c.members or None
    return fit_candidate([c.effects[0].name], residual, base.factors, tol, starts, members=members)


def refine(parts: Parts, cal: Calibrated, scores: Scores, say: Progress) -> Scores:
    """Stage 4: the best few refitted with all the tolerances jointly; then the tolerances
    again from where those refits put them (without their effects): if that fits the
    calibration part better, it is the simulator to beat, and every single is scored again
    against it.  Nothing to refine when the calibrated simulator is within the noise."""
    base = scores.baseline
    if within_noise(base.nominal, cal.floor):
        return scores
    singles, sums, smooth = list(scores.singles), dict(scores.sums), dict(scores.smooth)
    for i, c in enumerate(singles[:REFINE_TOP]):
        r = _refit(c, parts, cal, base)
        both = held_sums(r, cal, base)
        say(f"refit {r.name} with tolerances: held-out reduction {r.heldout_reduction:+.2f}")
        if r.criterion < c.criterion:
            singles[i] = r
            sums[c.name], smooth[c.name] = both
    from_refits = [(base.factors, ())] + [(c.factors, ()) for c in singles[:REFINE_TOP]]
    fit_ev = cal.readings.fit(None)
    tol = cal_mod.knobs(base.factors)
    recal = fit_candidate([], fit_ev.residual, base.factors, tol, from_refits)
    if recal.fit_cost < base.cal.fit_cost:
        base = make_baseline(cal.prep, parts, cal.readings.held(None), cal.floor, recal)
        say("recalibrated " + percent(base.factors))
        for c in singles:
            score(c, sums[c.name], cal.floor, base.gap0, base.n_eff)
        singles.sort(key=lambda c: c.criterion)
    return Scores(singles=singles, sums=sums, smooth=smooth, baseline=base)


def fit_pairs(parts: Parts, cal: Calibrated, scores: Scores, say: Progress) -> Paired:
    """Stage 5: pairs, when the best alone explains the gap but leaves some clearly above
    the noise (``pair_plan``); the bootstrap resamples the verdict weighs them with."""
    base, singles, floor = scores.baseline, scores.singles, cal.floor
    idx = resamples(len(parts.heldout))
    sums, smooth = dict(scores.sums), dict(scores.smooth)
    pairs: list[Candidate] = []
    if not within_noise(base.nominal, floor):
        by_name = {c.effects[0].name: c for c in singles}
        residual = cal.readings.fit(None).residual
        for a, b in pair_plan(singles, sums[singles[0].name], floor, base.nominal, idx):
            first, other = by_name[a], by_name[b]
            starts = [(first.factors, (*first.effects, *other.effects))]
            members = [m for x in (first, other) for m in (x.members or member_defaults(x))]
            c = fit_candidate([a, b], residual, first.factors, (), starts, members=members)
            sums[c.name], smooth[c.name] = held_sums(c, cal, base)
            pairs.append(c)
            say(f"pair {c.name}: held-out reduction {c.heldout_reduction:+.2f}")
    return Paired(pairs=pairs, boot_idx=idx, sums=sums, smooth=smooth)


def member_defaults(c: Candidate) -> list[Member]:
    """The default formulation of each of a candidate's effects."""
    return [default_member(e.name) for e in c.effects]


def percent(factors: dict[str, float]) -> str:
    return ", ".join(f"{k} {100 * (v - 1):+.1f} %" for k, v in factors.items())


def with_prep(parts: Parts, cal: Calibrated) -> Parts:
    """The parts with the recording as every candidate read it."""
    return replace(parts, prep=cal.prep)
