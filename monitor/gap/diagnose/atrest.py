"""Stages 6e and 6f: what the recording shows with the spool centred and the rod at rest,
where no base mismatch of the valve's metering, the pump's response or the lines enters,
names an effect the held-out fits could not: a load that changes with the pose
(``judge/loadcheck.py``) and entrained air (``judge/aircheck.py``).

On the third plant written apart, both effects moved the held-out gap by less than that
plant's base dynamics did: the fitted slope removed 0-6 % of it (while the holds' load
changed by 2-5 kN over the stroke), the fitted air 3-17 % (while the drained chambers on the
stops rose 0.05-0.32 times as fast as the loaded ones fell, 2.5-5.5 times on healthy
machines).  So when the holds show such evidence, the effect is the verdict, whatever the
held-out criterion preferred; and a ``load_variation`` verdict on holds that clearly show
one load everywhere is decided again without it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from monitor.gap.diagnose.records import Calibrated, Paired, Parts, Scores
from monitor.gap.diagnose.verdict import Judged
from monitor.gap.judge import aircheck, loadcheck
from monitor.gap.judge.decide import Decision, decide

Progress = Callable[[str], None]


def check_load(
    parts: Parts, cal: Calibrated, scores: Scores, paired: Paired, judged: Judged, say: Progress
) -> Judged:
    """The verdict checked against the rod's holds; the JSON's ``load_check``."""
    if judged.noise_only:
        return judged
    sig = loadcheck.signature(cal.readings.prep, parts.segments, cal.fit_machine)
    d = judged.decision
    load = next((c for c in scores.singles if c.name == loadcheck.NAME), None)
    named = loadcheck.NAME in (d.verdict, d.also)
    if sig.present and not named and load is not None:
        d = Decision(loadcheck.NAME, None, load, sig.above_share)
    elif named and sig.absent:
        d = _without(loadcheck.NAME, cal, scores, paired, judged)
    checked = {
        **sig.as_dict(),
        "verdict_without_check": judged.decision.verdict,
        "load_named": loadcheck.NAME in (d.verdict, d.also),
    }
    say(f"load: {sig.evidence()}; verdict {judged.decision.verdict} -> {d.verdict}")
    return replace(judged, decision=d, load=checked)


def _without(
    name: str, cal: Calibrated, scores: Scores, paired: Paired, judged: Judged
) -> Decision:
    """The verdict decided again from every single and pair without effect ``name``."""
    base = scores.baseline
    against = {c: a.sums for c, a in judged.absorbed.items()}
    return decide(
        False,
        [c for c in scores.singles if c.effects[0].name != name],
        [q for q in paired.pairs if all(e.name != name for e in q.effects)],
        paired.sums,
        base.nominal,
        paired.boot_idx,
        cal.floor,
        (paired.smooth, base.smooth_nominal),
        against,
    )


def check_air(cal: Calibrated, scores: Scores, judged: Judged, say: Progress) -> Judged:
    """The verdict checked against the drained chambers on the end stops; the JSON's
    ``air_check``.  It only names: where nothing leaks at rest (this simulator, the
    outsider's plant) it reads nothing, and air is judged by the held-out fits alone."""
    if judged.noise_only:
        return judged
    sig = aircheck.signature(cal.readings.prep, cal.fit_machine)
    d = judged.decision
    air = next((c for c in scores.singles if c.name == aircheck.NAME), None)
    if sig.present and aircheck.NAME not in (d.verdict, d.also) and air is not None:
        d = Decision(aircheck.NAME, None, air, sig.below_share)
    checked = {
        **sig.as_dict(),
        "verdict_without_check": judged.decision.verdict,
        "air_named": aircheck.NAME in (d.verdict, d.also),
    }
    say(f"air: {sig.evidence()}; verdict {judged.decision.verdict} -> {d.verdict}")
    return replace(judged, decision=d, air=checked)
