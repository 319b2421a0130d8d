"""Stage 6e: the rod's load read at rest (``judge/loadcheck.py``) names or withdraws
``load_variation``.

A load that changes with the boom's pose shows in the holds' force balance, which no base
mismatch of valve, pump or lines enters; the fitted slope alone could remove only a few
percent of a held-out gap such a mismatch dominates (the third plant: 0-6 %).  So when the
holds show a load change the tolerances cannot carry (the gravity load is one force at every
pose), ``load_variation`` is the verdict, whatever the held-out criterion preferred; and a
``load_variation`` verdict on holds that clearly show none is decided again without it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from monitor.gap.diagnose.records import Calibrated, Paired, Parts, Scores
from monitor.gap.diagnose.verdict import Judged
from monitor.gap.judge import loadcheck
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
        base = scores.baseline
        rest = [c for c in scores.singles if c is not load]
        plain = [q for q in paired.pairs if all(e.name != loadcheck.NAME for e in q.effects)]
        against = {name: a.sums for name, a in judged.absorbed.items()}
        structured = (paired.smooth, base.smooth_nominal)
        args = (paired.sums, base.nominal, paired.boot_idx, cal.floor, structured, against)
        d = decide(False, rest, plain, *args)
    checked = {
        **sig.as_dict(),
        "verdict_without_check": judged.decision.verdict,
        "load_named": loadcheck.NAME in (d.verdict, d.also),
    }
    say(f"load: {sig.evidence()}; verdict {judged.decision.verdict} -> {d.verdict}")
    return replace(judged, decision=d, load=checked)
