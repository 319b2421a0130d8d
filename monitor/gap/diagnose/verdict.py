"""The diagnosis's judging stages: the verdict (with the calibration's absorbed effects and
the sensor-lag check), then what to model next and the sensor-or-physics check.

Verdict rules: see ``judge/decide.py``."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from monitor.gap.data.prepare import ROD_VEL
from monitor.gap.diagnose import cause as cause_mod
from monitor.gap.diagnose.evaluate import Readings
from monitor.gap.diagnose.records import Absorbed, Calibrated, Finding, Paired, Parts, Scores
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit import score as S
from monitor.gap.fit import sensorcal
from monitor.gap.fit.candidates import CONFOUNDED, Candidate
from monitor.gap.judge import delays, friction, lagcheck, sensorphysics
from monitor.gap.judge.decide import Decision, boot_gain, decide, explains, within_noise
from monitor.gap.judge.suggest import suggest

Progress = Callable[[str], None]

#: An effect's fit moved a tolerance off the bound the calibration left it at when it moved
#: it by this share of the band (a friction's fit took viscous friction from +30 % to +19 %
#: or below; a hose's left volumes at +14.3-14.6 % of +15 %, where nothing stood in).
MOVED_OFF = 0.25


@dataclass(frozen=True)
class Judged:
    """The decision before the suggestion stage, and what it was checked against."""

    decision: Decision
    #: The JSON's ``lag_check`` (None: not checked).
    lag_check: dict | None
    absorbed: dict[str, Absorbed]
    noise_only: bool
    #: An ``oil_viscosity`` verdict's leak checked against the oil temperature (``cause``).
    cause: cause_mod.LeakCause | None = None
    #: A ``sensor_lag`` verdict checked against the rod's timing: the JSON's
    #: ``timing_check`` (None: not checked).
    timing: dict | None = None
    #: The rod's friction read from its force balance (``judge/friction.py``): the JSON's
    #: ``friction_check`` (None: not read, the simulator within the noise).
    friction: dict | None = None
    #: Which readings are late and what the others share (``diagnose/timing.py``): the
    #: JSON's ``timing`` (None: not measured).
    split: dict | None = None
    #: The rod's load read at rest (``diagnose/atrest.py``): the JSON's ``load_check``.
    load: dict | None = None
    #: The drained chambers' stiffness at rest (``diagnose/atrest.py``): ``air_check``.
    air: dict | None = None
    #: The best single, a sensor calibration, judged on its own signal
    #: (``sensorphysics.own_signal``; None: not judged so).
    own_signal: sensorphysics.OwnSignal | sensorphysics.RodKinematics | None = None
    #: A deadband against a progressive metering curve (``deadband.check_metering``).
    metering: dict | None = None
    #: A pump leakage against a healthy pump's slip (``slip.check_slip``): the JSON's
    #: ``slip_check`` (None: not checked).
    slip: dict | None = None


def judge(cal: Calibrated, scores: Scores, paired: Paired, say: Progress) -> Judged:
    """Stage 6: the verdict from the held-out scores (``decide``), then checked against
    the engine's speed ripple where a sensor lag is in question (``lagcheck``)."""
    base, floor = scores.baseline, cal.floor
    noise_only = within_noise(base.nominal, floor)
    absorbed = (
        {} if noise_only else calibration_absorbed(scores.singles, base.factors, cal.readings)
    )
    against = {name: a.sums for name, a in absorbed.items()}
    structured = (paired.smooth, base.smooth_nominal)
    d = decide(
        noise_only,
        scores.singles,
        paired.pairs,
        paired.sums,
        base.nominal,
        paired.boot_idx,
        floor,
        structured,
        against,
    )
    chk = None if noise_only else _lag_check(d, cal, scores, paired)
    lag_checked = None
    if chk is not None:
        before = d.verdict
        d = _after_lag_check(d, chk, scores, paired, cal, against)
        lag_checked = {
            **chk.as_dict(),
            "verdict_without_check": before,
            "sensor_named": d.verdict == lagcheck.NAME,
        }
        say(
            f"sensor lag against the engine's speed ripple: readings {lag_checked['readings']}"
            f"; verdict {before} -> {d.verdict}"
        )
    own = _own_signal(d, scores, paired, cal)
    if own is not None and own.named:
        say(f"sensor calibration judged on its own signal: {own.evidence()}")
        sensor = next(c for c in scores.singles if c.effects[0].name == sensorcal.NAME)
        d = Decision(sensorcal.NAME, None, sensor, own.share)
    return Judged(
        decision=d, lag_check=lag_checked, absorbed=absorbed, noise_only=noise_only, own_signal=own
    )


def _own_signal(
    d: Decision, scores: Scores, paired: Paired, cal: Calibrated
) -> sensorphysics.OwnSignal | sensorphysics.RodKinematics | None:
    """An ``unexplained`` gap whose best single is a sensor calibration, or whose sensor
    calibration is of a reading later than the others (``delays.Split.some_late``; a lag
    or a slow spool then ranks above it on that reading's timing): that calibration judged
    on the one signal it reads, each of the simulator and the hypothesis aligned by its own
    delay (``sensorphysics.own_signal``)."""
    if d.verdict != "unexplained" or not scores.singles:
        return None
    prep, base = cal.prep, scores.baseline
    held = cal.readings.held(None).segments
    lags = delays.delays_ms(prep, held, base.pred0)
    sensor = _own_candidate(scores.singles, lags)
    if sensor is None:
        return None
    signal = sensor.effects[0].labels["signal"]
    if signal == "RodPos":
        return sensorphysics.rod_kinematics(sensor, prep, held, base.pred0, paired.boot_idx)
    names = S.compared(prep)
    if signal not in names:
        return None
    # Each of the calibrated simulator and the hypothesis aligned by its own delay.
    ev = cal.readings.held(sensor.prep)
    pred = ev.predict(sensor.factors, sensor.effects)
    before, _ = sensorphysics.aligned_sums(prep, held, base.pred0, signal)
    after, ms = sensorphysics.aligned_sums(ev.prep, held, pred, signal)
    return sensorphysics.own_signal(
        sensor, names, before, after, paired.boot_idx, cal.floor, aligned_ms=ms
    )


def _own_candidate(singles: Sequence[Candidate], lags: dict[str, float | None]) -> Candidate | None:
    """The sensor calibration single judged on its own signal: the best single, or one of
    a reading the timing shows late (None: neither)."""
    if singles[0].effects[0].name == sensorcal.NAME:
        return singles[0]
    sensor = next((c for c in singles if c.effects[0].name == sensorcal.NAME), None)
    late = delays.split(lags)
    if sensor is None or late is None or not late.some_late:
        return None
    # Later than the others: every reading late is a shared delay or a lag of them all,
    # both chambers late a compliance of the lines (``Split.some_late``).
    return sensor if sensor.effects[0].labels["signal"] in late.late else None


def check_cause(
    parts: Parts, cal: Calibrated, scores: Scores, paired: Paired, judged: Judged, say: Progress
) -> Judged:
    """Stage 6b: cause second (``cause.py``): a leak named ``oil_viscosity`` that does not
    follow the oil temperature is wear, not viscosity."""
    d, chk = cause_mod.judge_cause(judged.decision, parts, cal, scores, paired.boot_idx, say)
    return replace(judged, decision=d, cause=chk)


def check_timing(
    cal: Calibrated, scores: Scores, paired: Paired, judged: Judged, say: Progress
) -> Judged:
    """Stage 6c: a sensor lag delays the readings, not the machine.  A ``sensor_lag``
    verdict where the measured rod moves as late as the pressures read (against the
    calibrated simulator, ``delays.py``) is the machine being late (a slow spool or pump):
    it is decided again without the sensor lag.  Needs RodPos."""
    d = judged.decision
    prep = cal.readings.prep
    if d.verdict != lagcheck.NAME or ROD_VEL not in prep.meas:
        return judged
    base = scores.baseline
    lags = delays.delays_ms(prep, cal.readings.held(None).segments, base.pred0)
    machine_late = delays.machine_late(lags)
    if machine_late is None:
        return judged
    timing = {"delays_ms": lags, "rod_shares_lag": machine_late, "verdict_without_check": d.verdict}
    if machine_late:
        lag_c = _lag_candidate(scores.singles)
        rest = [c for c in scores.singles if c is not lag_c]
        plain = [q for q in paired.pairs if all(e.name != lagcheck.NAME for e in q.effects)]
        against = {name: a.sums for name, a in judged.absorbed.items()}
        structured = (paired.smooth, base.smooth_nominal)
        args = (paired.sums, base.nominal, paired.boot_idx, cal.floor, structured, against)
        d = decide(False, rest, plain, *args)
    say(
        f"sensor lag against the rod's timing: {lags}; "
        f"verdict {timing['verdict_without_check']} -> {d.verdict}"
    )
    return replace(judged, decision=d, timing=timing)


def check_friction(
    parts: Parts, cal: Calibrated, scores: Scores, paired: Paired, judged: Judged, say: Progress
) -> Judged:
    """Stage 6d: friction acts at any speed, viscous friction with speed, and the rod's
    measured force balance tells them apart where the calibration cannot
    (``judge/friction.py``).  Where the verdict was ``none`` or ``unexplained``, a Coulomb
    friction no viscous friction carries (held in its band or free) names
    ``cylinder_friction``; one only the band refuses names it when the fitted friction
    gains significantly on the held-out part.  A ``cylinder_friction`` verdict on a rod
    whose balance shows none is decided again without it (more viscous friction, a mass,
    a valve gain stood in)."""
    if judged.noise_only:
        return judged
    sig = friction.signature(cal.readings.prep, parts.segments, cal.fit_machine)
    d = judged.decision
    fric = next((c for c in scores.singles if c.name == friction.NAME), None)
    base, idx, floor, sums = scores.baseline, paired.boot_idx, cal.floor, paired.sums
    against = {name: a.sums for name, a in judged.absorbed.items()}
    if d.verdict in ("none", "unexplained") and fric is not None:
        before = against[fric.name][0] if fric.name in against else base.nominal
        named = friction.named_by_signature(sig, fric, before, sums[fric.name], idx, floor)
        d = named or d
    elif friction.NAME in (d.verdict, d.also) and sig.absent:
        rest = [c for c in scores.singles if c is not fric]
        plain = [q for q in paired.pairs if all(e.name != friction.NAME for e in q.effects)]
        structured = (paired.smooth, base.smooth_nominal)
        d = decide(False, rest, plain, sums, base.nominal, idx, floor, structured, against)
    checked = {
        **sig.as_dict(),
        "verdict_without_check": judged.decision.verdict,
        "friction_named": friction.NAME in (d.verdict, d.also),
    }
    say(f"friction: {sig.evidence()}; verdict {judged.decision.verdict} -> {d.verdict}")
    return replace(judged, decision=d, friction=checked)


def _lag_candidate(singles: Sequence[Candidate]) -> Candidate | None:
    return next((c for c in singles if c.effects[0].name == lagcheck.NAME), None)


def _lag_check(
    d: Decision, cal: Calibrated, scores: Scores, paired: Paired
) -> lagcheck.LagCheck | None:
    """How the readings follow the engine's speed ripple: checked when ``sensor_lag`` is
    the verdict or explains the gap alone without being it (None: not checked)."""
    lag_c = _lag_candidate(scores.singles)
    if lag_c is None:
        return None
    base = scores.baseline
    gain = boot_gain(base.nominal, paired.sums[lag_c.name], paired.boot_idx, cal.floor)
    if d.verdict != lagcheck.NAME and not explains(lag_c, gain):
        return None
    lagged = cal.readings.held(lag_c.prep).predict(lag_c.factors, lag_c.effects)
    held = cal.readings.held(None).segments
    return lagcheck.check(cal.readings.prep, held, base.pred0, lagged)


def _after_lag_check(
    d: Decision,
    chk: lagcheck.LagCheck,
    scores: Scores,
    paired: Paired,
    cal: Calibrated,
    against: dict,
) -> Decision:
    """A lagged sensor reports the engine's speed ripple late, a slow spool (or any plant
    effect) leaves it prompt: a ``sensor_lag`` verdict with prompt readings is decided
    again without it; late readings name it, if it explains the gap alone."""
    lag_c = _lag_candidate(scores.singles)
    base, idx, floor, sums = scores.baseline, paired.boot_idx, cal.floor, paired.sums
    structured = (paired.smooth, base.smooth_nominal)
    if d.verdict == lagcheck.NAME and chk.prompt:
        rest = [c for c in scores.singles if c is not lag_c]
        plain = [p for p in paired.pairs if all(e.name != lagcheck.NAME for e in p.effects)]
        return decide(False, rest, plain, sums, base.nominal, idx, floor, structured, against)
    if d.verdict != lagcheck.NAME and chk.late and lag_c is not None:
        alone = decide(False, [lag_c], [], sums, base.nominal, idx, floor, structured, against)
        if alone.verdict == lagcheck.NAME:
            return alone
    return d


def suggest_next(
    parts: Parts, cal: Calibrated, scores: Scores, paired: Paired, judged: Judged, say: Progress
) -> Finding:
    """Stage 7: for ``unexplained`` (or a sensor calibration, to check it against the plant
    terms): what to model next (``suggest``); a sensor error moves one signal only, so a
    plant term that explains more of the held-out gap makes it ``unexplained``."""
    d, base, floor = judged.decision, scores.baseline, cal.floor
    lead = checked = None
    if d.verdict in ("unexplained", sensorcal.NAME):
        readings = cal.readings
        lead = suggest(
            cal.prep,
            (parts.fitted, readings.fit(None).plant, cal.fit_machine),
            (parts.heldout, readings.held(None).plant, cal.held_machine),
            base.factors,
            floor,
            base.gap0,
            base.n_eff,
            held_base=base.pred0,
            # A sensor check compares single terms; the partner of the best is tried only
            # if the verdict ends ``unexplained`` (below).
            pair=d.verdict == "unexplained",
        )
    if d.verdict == sensorcal.NAME and d.chosen is not None and lead is not None:
        sums = paired.sums[d.chosen.name]
        checked = sensorphysics.compare(d.chosen, sums, lead, paired.boot_idx, floor)
        if checked is not None and not checked.sensor_named:
            say(f"not a sensor error: {checked.term} explains more across the signals")
            d = Decision("unexplained", None, None, checked.plant_share)
    if d.verdict == "unexplained" and lead is not None:
        lead.with_pair()
        say("what to model next: " + (lead.ranked[0]["description"] if lead.ranked else "-"))
    chk = judged.cause
    ranked = lead.ranked if lead and d.verdict == "unexplained" else []
    if chk is not None and chk.cause != cause_mod.NAME and d.verdict == "unexplained":
        # The worn leak (or the leak of undecided cause) was fitted and scored like the
        # terms: it leads the suggestion.
        ranked = [cause_mod.suggestion_entry(chk), *ranked]
    return Finding(
        verdict=d.verdict,
        also=d.also,
        chosen=d.chosen,
        confidence=d.confidence,
        suggestion=ranked,
        suggestion_tried=lead.tried if lead else [],
        sensor_check=_sensor_check(checked, judged.own_signal, d, cal),
        traded=_traded(d, scores.singles, S.compared(cal.prep)),
        lag_check=judged.lag_check,
        cause_check=None if chk is None else chk.as_dict(),
        timing_check=judged.timing,
        friction_check=judged.friction,
        timing=judged.split,
        load_check=judged.load,
        air_check=judged.air,
        slip_check=judged.slip,
    )


def _sensor_check(
    checked: sensorphysics.Comparison | None,
    own: sensorphysics.OwnSignal | sensorphysics.RodKinematics | None,
    d: Decision,
    cal: Calibrated,
) -> dict | None:
    """The JSON's ``sensor_check``: the plant terms' comparison, with the evidence that
    named the calibration: its own signal's gap, or for RodPos the rod's stops."""
    if own is not None and own.named:
        out = checked.as_dict() if checked is not None else {"signal": own.signal}
        return {**out, **own.as_dict()}
    if checked is None:
        return None
    out = checked.as_dict()
    if d.verdict == sensorcal.NAME and d.chosen is not None and checked.signal == "RodPos":
        out["evidence"] = sensorphysics.rod_evidence(d.chosen.effects[0], cal.prep)
    return out


def calibration_absorbed(
    singles: Sequence[Candidate], factors: dict[str, float], readings: Readings
) -> dict[str, Absorbed]:
    """Per physical single effect whose fit moved a confounded tolerance off the bound the
    calibration (``factors``) left it at (by ``MOVED_OFF`` of the band), or gave back a
    shape the calibration took up (``calibrate.gave_back``): what its own
    tolerances do without it (one held-out simulation each; none on a machine whose
    calibration is inside its bands)."""
    out = {}
    for c in singles:
        name = c.effects[0].name
        moved = {
            t: (f0, f1)
            for t in CONFOUNDED.get(name, ())
            if _moved(t, f0 := factors.get(t, 1.0), f1 := c.factors.get(t, 1.0))
        }
        if moved and len(c.effects) == 1:
            out[c.name] = Absorbed(moved, readings.held(c.prep).both_sums(c.factors, ()))
    return out


def _moved(name: str, calibrated: float, fitted: float) -> bool:
    """An effect's fit moved tolerance ``name`` off the bound the calibration left it at, or
    gave back a shape the calibration took up."""
    off = abs(fitted - calibrated) >= MOVED_OFF * cal_mod.BY_NAME[name].band
    at_bound = cal_mod.bound_side(name, calibrated) != 0
    return (at_bound and off) or cal_mod.gave_back(name, calibrated, fitted)


def _traded(d: Decision, singles: Sequence[Candidate], names: Sequence[str]) -> dict | None:
    """The JSON ``trade_off``: which effect was not named, the signal it made worse."""
    if d.traded is None:
        return None
    name, worse = d.traded
    best = next(c for c in singles if c.effects[0].name == name)
    return {
        "effect": name,
        "member": best.members[0].name if best.members else "default",
        "heldout_reduction": round(float(best.heldout_reduction), 4),
        "signal": names[worse.signal],
        "growth_share": round(worse.growth, 4),
        "bootstrap_share": round(worse.share, 3),
    }
