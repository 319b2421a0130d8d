"""Stage 6c': which readings are late, and what the lateness is (``judge/delays.py``).

Sensor dynamics delay the reading, not the machine.  Per signal, the delay against the
calibrated simulator on the held-out part (``delays.delays_ms``) is split into the readings
later than the rod (RodPos, read by its own sensor; without it, than the readings' median)
and the delay the others share (``delays.split``):

- **Some readings late, the rod and the other readings on time** (confirmed by each
  reading's delay fitted on the calibration part, 1 ms grid): a lag those sensors have and
  the machine does not.  The catalogue's ``sensor_lag`` reads all four late; the lag on
  the late readings alone (their fitted delay) is scored on the held-out part like any
  candidate (one sensor-only evaluation: the plant runs are the baseline's) and named
  ``sensor_lag`` on those signals when ``decide`` would name it alone and, where another
  effect was named, it beats that effect in ``SIGNIFICANT`` of the bootstrap resamples.
  Both cylinder chambers among the late readings is what a compliance of the lines does
  too: not read as a sensor.
- **Every reading late by the same 5-25 ms, the rod included** (without a rod: unless the
  readings follow the engine's ripple late, ``lag_check``, as lagged sensors would): the
  recording's timing (its clock against the commands, the transducers' electronics), not
  a fault.  The calibrated simulator's held-out readings are re-timed, each by its delay
  fitted on the calibration part (no simulation).  A slow spool or pump, or the
  all-readings lag, that does not clearly beat that re-timing (a gain in ``SIGNIFICANT``
  of the resamples and a practical share of what it leaves) is the delay: the verdict is
  what ``decide`` says of the re-timed simulator without an effect.  An ``unexplained``
  gap whose every suggested term (with none suggested, the best term tried) is a reading's
  delay, where the re-timing gains in
  ``SIGNIFICANT`` of the resamples, is ``none``: what is left is the base mismatch of a
  healthy machine of another make (the third plant's healthy machines: 8-20 ms late on
  every signal, a QP delay the only suggestion).  Otherwise the shared delay stays a
  timing note beside the verdict.

- **A deadband verdict where the readings share a delay** (``deadband.py``): it stands only
  where it shows (the moves out of a centred spool start later than the returns to centre,
  or the flows at held commands fall short as the overlap makes them) and it clearly beats
  the re-timed simulator; otherwise the verdict is the re-timed simulator's.

The JSON's ``timing`` holds the delays, the split, what was tried and what decided.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from monitor.gap.diagnose import deadband
from monitor.gap.diagnose.evaluate import Sums, score
from monitor.gap.diagnose.records import Calibrated, Finding, Paired, Scores
from monitor.gap.diagnose.verdict import Judged
from monitor.gap.fit import score as S
from monitor.gap.fit.calibrate import TOLERANCES
from monitor.gap.fit.candidates import Candidate
from monitor.gap.fit.sensorterms import SensorTerm
from monitor.gap.judge import basemis, delays, lagcheck, onsets
from monitor.gap.judge.decide import SIGNIFICANT, Decision, decide, gain_share, not_named
from monitor.sim.effects import Effect

Progress = Callable[[str], None]

#: The catalogue effect the split names.
NAME = "sensor_lag"
#: The effect whose timing signature is weighed against a shared delay (``onsets``).
DEADBAND = "valve_deadband"
#: Verdicts of a machine (or all its readings) running late, which a delay every reading
#: shares, the rod included, can stand behind.
MACHINE_DELAY = ("spool_dynamics", "pump_control_dynamics", NAME)
#: A pump displacement or one valve edge's gain within this (% change) is a tolerance, like
#: the valve's gain the calibration fits within its band (``calibrate.TOLERANCES``), all
#: four edges together: a machine's edges are not all off alike.
TOLERANCE_PCT = 100.0 * next(t.band for t in TOLERANCES if t.name == "valve_gain")


def check_split(cal: Calibrated, scores: Scores, paired: Paired, judged: Judged, say: Progress):
    """Stage 6c': some readings late (a sensor on them), or a machine-delay verdict that a
    delay every reading shares does as well as (the recording's timing): see the module."""
    if judged.noise_only:
        return judged
    prep, base = cal.readings.prep, scores.baseline
    lags = delays.delays_ms(prep, cal.readings.held(None).segments, base.pred0)
    sp = delays.split(lags)
    if sp is None:
        return judged
    d = judged.decision
    out: dict = {"delays_ms": lags, **sp.as_dict(), "verdict_without_check": d.verdict}
    if sp.some_late:
        fitted = _fitted(S.compared(prep), cal, scores)
        d, out["sensor_lag_on_late"] = _sensor_on(sp, fitted, cal, scores, paired, d)
    elif sp.shared and (sp.reference == "rod" or not _ripple_late(judged, cal, scores, out)):
        # A rod as late as the pressures is the acquisition; without it, readings following
        # the ripple later than the shared delay makes them may be lagged, and the lag stands.
        fitted = out.get("ripple", {}).get("delays_ms") or _fitted(S.compared(prep), cal, scores)
        if "ripple" in out and d.verdict == NAME:  # lines first, as below (s924107_20's hose)
            d, lines = _lag_or_lines(d, cal, scores, paired, judged)
            out.update({"lines": lines} if d.verdict != NAME else {})
        whole, smooth = _retimed(fitted, cal, scores)
        out["retimed"] = {"delays_ms": fitted, **_retimed_row(whole, smooth, cal, scores, paired)}
        if d.verdict in MACHINE_DELAY and d.chosen is not None:
            d = _delay_or_machine(d, whole, smooth, cal, paired, out["retimed"])
    elif _chambers_only(sp):
        # Only the chambers late, the rest (the rod among them) sharing the recording's
        # delay: not a sensor (``Split.some_late``) but the lines or chambers of another
        # make; the re-timed simulator is what stage 7b weighs an unexplained gap against
        # (the third plant's healthy s730896_61: PA, PB 20-27 ms, the rest 8-10 ms).
        _retimed_once(out, cal, scores, paired)
    if d.verdict == DEADBAND and d.chosen is not None and sp.shared_ms is not None:
        retimed = _retimed_once(out, cal, scores, paired)
        d, out["deadband"] = deadband.deadband_or_delay(d, sp, retimed, cal, scores, paired)
    on_late = out.get("sensor_lag_on_late") or {}
    if d.verdict == NAME and not on_late.get("named"):
        d, out["lines"] = _lag_or_lines(d, cal, scores, paired, judged)
    out["decided_by"] = evidence(out, d.verdict)
    say(f"timing: {out['decided_by']}; verdict {out['verdict_without_check']} -> {d.verdict}")
    return replace(judged, decision=d, split=out)


def check_shared(finding: Finding, say: Progress) -> Finding:
    """Stage 7b: an ``unexplained`` gap whose every suggested term (or, with none suggested,
    the best term tried) is a reading's delay or a tolerance the calibration does not fit,
    on a recording whose readings share a 5-25 ms delay (the rod included) that, re-timed,
    gains significantly: the recording's timing and the base mismatch, not a fault.  A
    pump displacement or one valve edge's gain within the band the calibration grants the
    valve's gain is such a tolerance, not a departure (the third plant's healthy
    s730896_60: displacement -4.4 %, s924107_65: the P->A edge -12.8 %, each paired with a
    15 ms QP delay).  Alone too: a machine 12 % off nominal has its pump and each valve
    edge off by up to that, and the calibration fits all four edges alike and the pump
    not at all (s336080_65: displacement +3.9 % suggested, 51 % of the held-out gap;
    s336080_61: nothing suggested, an A->tank edge +4.3 % the best tried)."""
    t = finding.timing
    if finding.verdict != "unexplained" or not t or not t.get("retimed"):
        return finding
    # Nothing suggested and a reading's delay the best term tried is the same: the only
    # structure any term finds is the timing (the third plant's healthy machine s924107_64:
    # a QP delay removed 17 % of what re-timing leaves, every plant term 0 % or less).
    terms = finding.suggestion or finding.suggestion_tried[:1]
    delays_in = [s for s in terms if s.get("term") == "sensor_delay"]
    within = [s for s in terms if _within_tolerance(s)]
    r = t["retimed"]
    if not (terms and len(delays_in) + len(within) == len(terms)):
        return finding
    if r["gain_share"] < SIGNIFICANT:
        return finding
    if "deadband" not in t:  # a deadband not named keeps the verdict it stood in for
        t = {**t, "verdict_without_check": finding.verdict}
    t["tolerance_terms"] = [
        {k: s[k] for k in ("term", "signal", "coefficient", "unit") if k in s} for s in within
    ]
    t["decided_by"] = evidence(t, "none") + "".join(
        f"; {s['description']}: within the {TOLERANCE_PCT:.0f} % the calibration grants the "
        "valve's gain, a tolerance"
        for s in within
    )
    say(f"timing: {t['decided_by']}; verdict unexplained -> none")
    return replace(
        finding, verdict="none", chosen=None, confidence=r["gain_share"], suggestion=[], timing=t
    )


def _within_tolerance(term: dict) -> bool:
    """A suggested pump displacement or valve edge gain within ``TOLERANCE_PCT``."""
    kind = (term.get("term"), term.get("signal"))
    return (kind == ("pump_setting", "displacement") or kind[0] == "valve_setting") and abs(
        float(term.get("coefficient", np.inf))
    ) <= TOLERANCE_PCT


def _ripple_late(judged: Judged, cal: Calibrated, scores: Scores, out: dict) -> bool:
    """The readings follow the engine's ripple late (``lagcheck``) against the simulator
    re-timed by each reading's fitted delay too: a delay of one sample turns a white
    ripple's lag-zero response to minus half of it, which no first-order lag does (the
    third plant's healthy s730896_62: QP -0.40 against +0.75 undelayed, -0.28 re-timed)."""
    if not (judged.lag_check and judged.lag_check.get("readings") == "late"):
        return False
    lag_c = next((c for c in scores.singles if c.effects[0].name == NAME), None)
    if lag_c is None:
        return True
    fitted = _fitted(S.compared(cal.prep), cal, scores)
    held = cal.readings.held(None).segments
    lagged = cal.readings.held(lag_c.prep).predict(lag_c.factors, lag_c.effects)
    chk = lagcheck.check(cal.readings.prep, held, _retimed_pred(fitted, cal, scores), lagged)
    out["ripple"] = {"delays_ms": fitted, "against": "re-timed", **chk.as_dict()}
    return chk.late


def _fitted(signals, cal: Calibrated, scores: Scores) -> dict[str, float]:
    """Each signal's delay fitted on the calibration part (``delays.fitted_ms``): the held-out
    part only judges (one plant run of the calibration part at most, usually cached)."""
    fit_ev = cal.readings.fit(None)
    pred = fit_ev.predict(scores.baseline.factors, ())
    return delays.fitted_ms(cal.readings.prep, fit_ev.segments, pred, signals)


def _sensor_on(
    sp: delays.Split, fitted: dict, cal: Calibrated, scores: Scores, paired: Paired, d: Decision
) -> tuple[Decision, dict]:
    """A lag on the late readings alone, scored and judged like a candidate: those whose
    delay fitted on the calibration part confirms them late (by ``APART_MS`` against the
    rod's fitted delay, or the readings' median) are tried; the correlation peaks of a
    healthy machine scatter by several ms (one 10 ms apart on the outsider's plant, its
    fitted delay 0 ms)."""
    base, floor, idx = scores.baseline, cal.floor, paired.boot_idx
    ref = fitted.get("RodVel") if sp.reference == "rod" else None
    if ref is None:
        ref = float(np.median([fitted[s] for s in delays.READINGS if s in fitted]))
    late = [s for s in sp.late if fitted[s] - ref >= delays.APART_MS]
    if not late:
        return d, {"signals": [], "fitted_ms": fitted, "named": False}
    delay = float(np.median([fitted[s] for s in late]))
    eff = Effect(NAME, {"delay_ms": delay, "time_constant_ms": 0.0}, {"signal": ",".join(late)})
    c = Candidate((eff,), dict(base.factors), float("nan"))
    whole, smooth = cal.readings.held(None).both_sums(c.factors, (eff,))
    score(c, whole, floor, base.gap0, base.n_eff)
    sums, smooths = {**paired.sums, c.name: whole}, {**paired.smooth, c.name: smooth}
    alone = decide(False, [c], [], sums, base.nominal, idx, floor, (smooths, base.smooth_nominal))
    beats = 1.0
    if d.chosen is not None:
        beats = gain_share(paired.sums[d.chosen.name], whole, idx, floor)
    named = alone.verdict == NAME and beats >= SIGNIFICANT
    tried = {
        "signals": late,
        "fitted_ms": fitted,
        "delay_ms": round(delay, 1),
        "heldout_reduction": round(float(c.heldout_reduction), 4),
        "beats_verdict_share": round(beats, 3),
        "named": named,
    }
    return (alone if named else d), tried


def _retimed(fitted: dict[str, float], cal: Calibrated, scores: Scores) -> Sums:
    """``_retimed_pred``'s whole and smoothed sums."""
    prep, pred = cal.readings.prep, _retimed_pred(fitted, cal, scores)
    held = cal.readings.held(None).segments
    return S.segment_sums(prep, held, pred), basemis.smoothed_sums(prep, held, pred)


def _retimed_pred(fitted: dict[str, float], cal: Calibrated, scores: Scores) -> dict:
    """The calibrated simulator's held-out readings, each delayed by its delay fitted on the
    calibration part."""
    prep, held = cal.readings.prep, cal.readings.held(None).segments
    pred = scores.baseline.pred0
    for name, ms in fitted.items():
        if ms > 0.0:
            pred = SensorTerm("sensor_delay", name, ms).apply(prep, held, pred)
    return pred


def _chambers_only(sp: delays.Split) -> bool:
    """The late readings are the cylinder chambers alone, the rest sharing a delay of
    ``delays.SHARED_MIN_MS`` to ``delays.SHARED_MAX_MS``."""
    return (
        set(sp.late) == delays.CHAMBERS
        and sp.shared_ms is not None
        and delays.SHARED_MIN_MS <= sp.shared_ms <= delays.SHARED_MAX_MS
    )


def _retimed_once(out: dict, cal: Calibrated, scores: Scores, paired: Paired):
    """Each reading's fitted delay and the re-timed simulator's sums, ``out["retimed"]``
    filled in if the shared-delay check did not."""
    if "retimed" not in out:
        fitted = _fitted(S.compared(cal.prep), cal, scores)
        whole, smooth = _retimed(fitted, cal, scores)
        out["retimed"] = {"delays_ms": fitted, **_retimed_row(whole, smooth, cal, scores, paired)}
        return fitted, whole, smooth
    fitted = out["retimed"]["delays_ms"]
    return (fitted, *_retimed(fitted, cal, scores))


def _retimed_row(
    whole: S.SegmentSums, smooth: S.SegmentSums, cal: Calibrated, scores: Scores, paired: Paired
) -> dict:
    """What re-timing removes, its bootstrap gain share and what ``decide`` says of it."""
    base, floor, idx = scores.baseline, cal.floor, paired.boot_idx
    # ``decide``'s own rule for a gap no effect explains, on the re-timed simulator.
    alone = not_named(whole, idx, floor, ({}, smooth), np.zeros(len(idx)), None, None)
    return {
        "heldout_reduction": round(S.reduction(base.gap0, S.gap(whole.mse(), floor)), 4),
        "gain_share": round(gain_share(base.nominal, whole, idx, floor), 3),
        "verdict": alone.verdict,
    }


def _delay_or_machine(
    d: Decision,
    whole: S.SegmentSums,
    smooth: S.SegmentSums,
    cal: Calibrated,
    paired: Paired,
    row: dict,
) -> Decision:
    """A slow spool or pump (or an all-readings lag) that does not clearly beat re-timing the
    readings by their shared delay is that delay: judged again as the re-timed simulator.
    Clearly: a gain in ``SIGNIFICANT`` of the resamples, and what it removes from the
    re-timed simulator's structured gap reaching the practical level (``decide``'s bar for
    any effect): a 17 Hz spool fitted to a 15 ms delay of every reading gained in every
    resample over the re-timing, which had removed 97 % of the gap."""
    assert d.chosen is not None
    name, idx, floor = d.chosen.name, paired.boot_idx, cal.floor
    beats = gain_share(whole, paired.sums[name], idx, floor)
    effect_s = paired.smooth.get(name)
    practical = effect_s is not None and basemis.removes_practical(
        smooth, effect_s, basemis.smoothed_floor(floor)
    )
    row["effect_beats_share"] = round(beats, 3)
    row["effect_removes_practical"] = practical
    if beats >= SIGNIFICANT and practical:
        return d
    alone = not_named(whole, idx, floor, ({}, smooth), np.zeros(1), None, None)
    return Decision(alone.verdict, None, None, float(alone.confidence))


def _lag_or_lines(
    d: Decision, cal: Calibrated, scores: Scores, paired: Paired, judged: Judged
) -> tuple[Decision, dict | None]:
    """A lag of every reading delays each by the same at every event: where, at the
    returns to centre, the pump's readings (PP, QP) are ``APART_MS`` later than the
    chambers' (PA, PB) in ``SIGNIFICANT`` of the resamples of the events
    (``onsets.chambers_apart``), the readings are not what is late but the lines between
    pump and cylinder (a compliance): the verdict is decided again without the sensor lag.
    The third plant's soft hoses were named ``sensor_lag`` by the engine's ripple, which
    that plant's pump does not follow as this simulator's does."""
    base = scores.baseline
    row = onsets.chambers_apart(cal.prep, cal.readings.held(None).segments, base.pred0)
    if row is None or row["apart_share"] < SIGNIFICANT:
        return d, row
    rest = [c for c in scores.singles if all(e.name != NAME for e in c.effects)]
    plain = [q for q in paired.pairs if all(e.name != NAME for e in q.effects)]
    against = {name: a.sums for name, a in judged.absorbed.items()}
    structured = (paired.smooth, base.smooth_nominal)
    args = (paired.sums, base.nominal, paired.boot_idx, cal.floor, structured, against)
    return decide(False, rest, plain, *args), row


def _lines_evidence(t: dict, verdict: str) -> str:
    """One line: the pump's readings against the chambers' at the returns to centre."""
    b = t["lines"]
    head = (
        f"at the returns to centre PP and QP read {b['pump_closing_ms']:.0f} ms late, PA "
        f"and PB {b['chambers_closing_ms']:.0f} ms"
    )
    if b["apart_share"] >= SIGNIFICANT:
        return (
            f"{head}: not a lag of the readings (it delays each alike) but of the lines "
            f"between pump and cylinder; verdict {verdict}"
        )
    return f"{head}: the readings late alike, as a sensor lag makes them"


def evidence(t: dict, verdict: str) -> str:
    """One line: what the readings' timing showed and what it decided."""
    if "deadband" in t:
        return deadband.evidence(t["deadband"], verdict)
    if t.get("lines"):
        return _lines_evidence(t, verdict)
    ref = "the rod" if t["reference"] == "rod" else "the readings' median"
    if "sensor_lag_on_late" in t and not t["sensor_lag_on_late"]["signals"]:
        return (
            f"{', '.join(t['late_signals'])} read later than {ref} by the correlation peak, "
            "not by the delay fitted on the calibration part: no reading is late"
        )
    if "sensor_lag_on_late" in t:
        s = t["sensor_lag_on_late"]
        on = ", ".join(s["signals"])
        head = f"{on} read {s['delay_ms']:.0f} ms late, later than {ref} by 10 ms or more"
        if s["named"]:
            return (
                f"{head}: a lag of {on} alone removes {s['heldout_reduction']:.0%} of the "
                f"held-out gap (a sensor's dynamics, not the machine's)"
            )
        return f"{head}; a lag of {on} alone does not explain the gap"
    if "retimed" in t:
        r = t["retimed"]
        ms = float(np.median(list(r["delays_ms"].values())))
        if t["late_signals"]:
            head = (
                f"{', '.join(t['late_signals'])} read later than {ref}, the rest about "
                f"{t['shared_ms']:.0f} ms late; each reading re-timed by its delay"
            )
        else:
            head = f"every reading about {ms:.0f} ms late against the simulator"
            head += ", the rod included" if t["reference"] == "rod" else ""
            head += "; re-timed by it"
        head += f", {r['heldout_reduction']:.0%} of the held-out gap goes"
        before = t["verdict_without_check"]
        if verdict == "none" and before == "unexplained":
            return (
                f"{head} and no term but a reading's delay or a tolerance the calibration does "
                "not fit explains the rest: the recording's timing and the base mismatch, not a "
                "fault"
            )
        if verdict != before:
            return (
                f"{head}, and {before} does not clearly beat that: a delay the whole "
                "recording shares (its timing), not a fault of the machine's dynamics"
            )
        return f"{head} (a timing note: the recording's delay, not a fault)"
    if t["late_signals"]:
        return f"{', '.join(t['late_signals'])} read later than {ref}"
    return f"the readings share a {t['shared_ms']} ms delay against the simulator"
