"""Stage 6c'', part of the timing check (``timing.py``): a ``valve_deadband`` verdict on a
recording whose readings share a delay.  A delay every reading shares and another make's
metering near centre are both fitted by a small overlap; a deadband stands only where it
shows in what a shared delay cannot do:

- **the openings and the closings** (``judge/onsets.py``): the moves out of a centred spool
  start later than the returns to centre by ``onsets.APART_MS`` in ``SIGNIFICANT`` of the
  resamples of the events (a shared delay shifts both alike).  Read where the spool crosses
  the overlap slowly; a spool ramped at 900 %/s crosses 10 % in one sample.
- **the held flows** (``judge/heldflow.py``): at held commands where the valve sets the
  flow, the flow falls short as an overlap (a probe, alone on the calibrated simulator)
  makes it, more at the smaller commands, reading an overlap of
  ``heldflow.MIN_OVERLAP_PCT`` or more in ``SIGNIFICANT`` of the resamples of the held
  levels.  No delay moves a settled flow, nor does a slow spool or pump once settled.

and it clearly beats the simulator re-timed by each reading's fitted delay (a gain in
``SIGNIFICANT`` of the resamples and a practical share of what re-timing leaves).  Otherwise
the verdict is what ``decide`` says of the re-timed simulator: the third plant's healthy
machines, 9-12 ms behind the simulator, were named a deadband of 3-6 % while their closings
were as late as their openings and their held flows read -1 to 2.4 %; its small deadbands
(s730896_13, 14, 44: openings 10-23 ms later than closings, not significant) read 5-7 %.

Stage 6e (``check_metering``): a deadband verdict where the held flows, read by the orifice
law, show notches and rule out an overlap is decided again without the deadband
(``heldflow.metering``; notches pass a small flow growing with the opening, an overlap
passes nothing below it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from monitor.gap.diagnose.records import Calibrated, Paired, Parts, Scores
from monitor.gap.diagnose.verdict import Judged
from monitor.gap.fit import score as S
from monitor.gap.fit.sensorterms import SensorTerm
from monitor.gap.judge import basemis, delays, flowforce, heldflow, onsets
from monitor.gap.judge.decide import SIGNIFICANT, Decision, decide, gain_share, not_named
from monitor.sim.effects import Effect
from monitor.sim.machine import BAR

NAME = "valve_deadband"
#: The calibration's tolerance for the valve's metering curve (``calibrate.TOLERANCES``).
METERING = "valve_metering"
#: The deadband's fit moved the calibration's notches by more than this (share of the
#: stroke): it is timed against its own tolerances (``deadband_or_delay``).
NOTCH_GIVEN_BACK = 0.05
#: The evidence a deadband can stand on (``timing.deadband.evidence``).
TIMING = "openings_and_closings"
HELD = "held_flows"


def deadband_or_delay(
    d: Decision,
    sp: delays.Split,
    retimed: tuple[dict[str, float], S.SegmentSums, S.SegmentSums],
    cal: Calibrated,
    scores: Scores,
    paired: Paired,
) -> tuple[Decision, dict]:
    """The deadband ``d`` names, weighed against the shared delay (see the module);
    ``retimed``: each reading's fitted delay and the re-timed simulator's sums."""
    assert d.chosen is not None
    c, base, held = d.chosen, scores.baseline, cal.readings.held(None).segments
    fitted, whole, smooth = retimed
    # Timed against the deadband's own tolerances without it where the calibration took up
    # notches the deadband's fit gave back: notches delay the flow at small openings as an
    # overlap does, and a calibrated simulator with them hides the overlap's timing.
    # It is weighed against that simulator re-timed, too (what the calibration absorbed).
    factors, ref = base.factors, base.pred0
    if abs(c.factors.get(METERING, 1.0) - factors.get(METERING, 1.0)) > NOTCH_GIVEN_BACK:
        factors = c.factors
        ref = cal.readings.held(None).predict(factors, ())
        whole, smooth = _retimed(cal, ref, fitted)
    measured = onsets.measure(cal.prep, held, ref)
    own = cal.readings.held(c.prep).predict(c.factors, c.effects)
    fitted_onsets = onsets.measure(cal.prep, held, ref, meas=own)
    flows = _held_flows(cal, factors, ref)
    shown = []
    if measured is None or measured.apart_share >= SIGNIFICANT:
        shown.append(TIMING)
    if flows is not None and flows.share >= SIGNIFICANT:
        shown.append(HELD)
    beats = gain_share(whole, paired.sums[c.name], paired.boot_idx, cal.floor)
    effect_s = paired.smooth.get(c.name)
    practical = effect_s is not None and basemis.removes_practical(
        smooth, effect_s, basemis.smoothed_floor(cal.floor)
    )
    named = bool(shown) and beats >= SIGNIFICANT and practical
    row = {
        "onsets": None if measured is None else measured.as_dict(),
        "fitted_onsets": None if fitted_onsets is None else fitted_onsets.as_dict(),
        "held_flows": None if flows is None else flows.as_dict(),
        "shared_ms": round(float(sp.shared_ms or 0.0), 1),
        "retimed_delays_ms": fitted,
        "beats_retimed_share": round(beats, 3),
        "removes_practical": practical,
        "named": named,
        "evidence": shown if named else [],
    }
    if named:
        return d, row
    alone = not_named(whole, paired.boot_idx, cal.floor, ({}, smooth), np.zeros(1), None, None)
    return Decision(alone.verdict, None, None, float(alone.confidence)), row


def _retimed(
    cal: Calibrated, pred: dict[str, np.ndarray], delays_ms: dict[str, float]
) -> tuple[S.SegmentSums, S.SegmentSums]:
    """``pred``'s held-out readings each delayed by its fitted delay: whole, smoothed sums."""
    prep, held = cal.prep, cal.readings.held(None).segments
    for name, ms in delays_ms.items():
        if ms > 0.0:
            pred = SensorTerm("sensor_delay", name, ms).apply(prep, held, pred)
    return S.segment_sums(prep, held, pred), basemis.smoothed_sums(prep, held, pred)


def _held_flows(
    cal: Calibrated, factors: dict[str, float], pred: dict[str, np.ndarray]
) -> heldflow.HeldFlow | None:
    """The held flows against the probe overlap alone on the simulator at ``factors``
    (``pred``; one simulation of the held-out part)."""
    held = cal.readings.held(None)
    probe = Effect.make(NAME, overlap_pct=heldflow.PROBE_PCT)
    overlapped = held.predict(factors, (probe,))
    return heldflow.measure(cal.prep, held.segments, pred, overlapped, heldflow.PROBE_PCT)


def _held_line(f: dict | None) -> str:
    if f is None:
        return "too few held commands where an overlap would matter"
    return (
        f"the flows at {f['held_levels']} held commands read an overlap of {f['overlap_pct']:.0f} %"
    )


def evidence(b: dict, verdict: str) -> str:
    """One line: the openings' and closings' timing, the held flows, and what they decided
    of a deadband."""
    o = b["onsets"]
    if o is None:
        head = "too few openings out of centre or returns to it to time"
    else:
        head = (
            f"moves out of a centred spool {o['opening_ms']:.0f} ms late against the "
            f"simulator, returns to centre {o['closing_ms']:.0f} ms"
        )
        f = b["fitted_onsets"]
        if f is not None:
            head += f" (the fitted deadband: {f['asymmetry_ms']:.0f} ms apart)"
    head += "; " + _held_line(b.get("held_flows"))
    vs = (
        "; against the simulator re-timed by the shared delay it gains in "
        f"{b['beats_retimed_share']:.0%} of resamples"
    )
    if b["named"]:
        by = " and ".join(
            "the openings later than the closings" if e == TIMING else "the held flows"
            for e in b["evidence"]
        )
        return f"{head}: a deadband's signature ({by}), not a shared delay{vs}"
    held = b.get("held_flows")
    if (o is not None and o["apart_share"] < SIGNIFICANT) and (
        held is None or held["share"] < SIGNIFICANT
    ):
        why = "a shared delay shifts openings and closings alike and moves no held flow"
    else:
        why = "it does not clearly beat that re-timing"
    rest = (
        ", and no term but a reading's delay explains what re-timing leaves (base mismatch)"
        if verdict == "none"
        else ""
    )
    return f"{head}: not a deadband ({why}){vs}{rest}; verdict {verdict}"


# --- Stage 6e: an overlap or notches ---------------------------------------------------


def check_metering(
    parts: Parts,
    cal: Calibrated,
    scores: Scores,
    paired: Paired,
    judged: Judged,
    say: Callable[[str], None],
) -> Judged:
    """Stage 6e: a deadband verdict against a progressive metering curve or a spool
    closed by flow forces.  An overlap passes nothing until the spool has crossed it;
    notches pass a small flow growing with the square of the opening, and a spool closed by
    flow forces passes less at a higher drop, not nothing.  Where the held levels, read by
    the orifice law on every segment, show notches and rule out an overlap
    (``heldflow.metering``, ``Metering.progressive``), or show flow forces and, read
    beside them, rule out an overlap (``flowforce.read``), the verdict is decided again
    without the deadband.  The JSON's ``metering_check`` (also, as evidence, where the
    calibration took up notches or the simulator's spool closes by flow forces)."""
    d, base, machine = judged.decision, scores.baseline, cal.readings.machine
    notch_pct = 100.0 * (base.factors.get(METERING, 1.0) - 1.0)
    deadband = d.verdict == NAME and d.chosen is not None
    forced = machine.valve.flow_force > 0.0
    if not deadband and notch_pct < 1.0 and not forced:
        return judged
    read = heldflow.metering(cal.prep, parts.segments, machine)
    progressive = read is not None and read.progressive
    forces = flowforce.read(cal.prep, parts.segments, machine) if deadband or forced else None
    # Flow through the edges below the overlap: with the flow forces read beside it, the
    # held flows rule an overlap out.
    ruled_out = forces is not None and forces.shown and forces.overlap_share <= heldflow.RULED_OUT
    row = {
        "verdict_without_check": d.verdict,
        "calibrated_notch_pct": round(notch_pct, 1),
        "fitted_overlap_pct": _fitted_overlap(d) if deadband else None,
        "held_flows": None if read is None else read.as_dict(),
        "progressive": progressive,
        "flow_forces": None if forces is None else forces.as_dict(),
        "simulated_flow_force_per_bar": round(machine.valve.flow_force * BAR, 4),
        "overlap_ruled_out": ruled_out,
    }
    if deadband and (progressive or ruled_out):
        rest = [c for c in scores.singles if c.name != NAME]
        plain = [q for q in paired.pairs if all(e.name != NAME for e in q.effects)]
        against = {name: a.sums for name, a in judged.absorbed.items()}
        structured = (paired.smooth, base.smooth_nominal)
        args = (paired.sums, base.nominal, paired.boot_idx, cal.floor, structured, against)
        d = decide(False, rest, plain, *args)
    row["decided_by"] = metering_line(row, d.verdict)
    say(f"metering: {row['decided_by']}")
    return replace(judged, decision=d, metering=row)


def _fitted_overlap(d: Decision) -> float | None:
    assert d.chosen is not None
    e = next((e for e in d.chosen.effects if e.name == NAME), None)
    return None if e is None else round(float(e.params["overlap_pct"]), 1)


def metering_line(row: dict, verdict: str) -> str:
    """One line: what the held flows read of the valve's curve near centre, and what it
    decided."""
    f = row["held_flows"]
    cal = f"the calibration took up notches over {row['calibrated_notch_pct']:.0f} % of the stroke"
    if row.get("flow_forces") is not None:
        forces = flowforce.line(row["flow_forces"])
        cal = forces if row["calibrated_notch_pct"] < 1.0 else f"{cal}; {forces}"
    if row.get("overlap_ruled_out") and row["verdict_without_check"] == NAME:
        return (
            f"{cal}: flow passes where the fitted overlap ({row['fitted_overlap_pct']} %) would "
            f"pass none at drops where the flow forces give flow, not a deadband; verdict {verdict}"
        )
    if f is None:
        return f"{cal}; too few held commands near centre to tell an overlap from notches"
    read = (
        f"{cal}; the flows at {f['held_levels']} held commands ({f['near_centre']} within "
        f"{100 * heldflow.NEAR_CENTRE:.0f} % of centre) read by the orifice law: overlap "
        f"{f['overlap_pct']:.0f} % with notches over {f['notch_pct']:.0f} % "
        f"(an overlap of {heldflow.MIN_OVERLAP_PCT:g} % or more in "
        f"{f['overlap_share']:.0%} of resamples, notches over {heldflow.MIN_NOTCH_PCT:g} % "
        f"or more in {f['notch_share']:.0%})"
    )
    if row["verdict_without_check"] != NAME:
        return read
    if row["progressive"]:
        return (
            f"{read}: flow passes where the fitted overlap ({row['fitted_overlap_pct']} %) "
            f"would pass none, a progressive metering curve, not a deadband; verdict {verdict}"
        )
    return f"{read}: the deadband stands"
