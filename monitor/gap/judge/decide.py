"""The verdict: ``none``, an effect (with perhaps a second one in ``also``), or
``unexplained``, each with a block-bootstrap confidence.

``none`` when the tolerance-calibrated simulator is within twice the sensor noise on every
signal, or within four times and no effect explains the rest.

An effect is named only when it removes a clear share of the held-out gap *and* its gain
over the tolerance-calibrated simulator is significant under the block bootstrap: a gain
that half of the resampled held-out parts do not show is tolerance or noise, not an effect.
A second effect is named only when the pair's gain over the best single effect is
significant in the same sense and removes a material share of the gap.

A physical effect is not named when, added to the simulator, it makes some compared signal
clearly worse (``consistency.py``): the machine's own physics moves every signal it acts
on towards the recording, so a fit that trades one signal for the others stands in for a
base mismatch (or something outside the catalogue) that lives where it gained.

With the smoothed (structured) sums (``basemis.py``), the same two tests also run on the
structured gap alone: an effect that removes most of what an effect can produce, but not
the base mismatch above 5 Hz, is named; and a gap that no effect explains is ``none``
when its structured part is below the practical level on every signal, or not clearly
above it: ``unexplained`` needs it above that level on some signal in ``SIGNIFICANT`` of
the block-bootstrap resamples (a healthy machine's PA at 0.021, carried by a few
segments, was above it in 65 % of them; out-of-catalogue gaps at 0.03-0.9 in all).

By either test, an effect is named only when what it removes from the structured gap
reaches that practical level (``basemis.removes_practical``): a healthy machine's base
mismatch is partly slow too, and an effect can take a share of it (entrained air, 18-26 %
of a held-out gap, through the structured test on machines without RodPos) while changing
the simulator by less than what would make it ``none`` had it been the whole structured gap.
An effect that removes that much, with a significant gain, and leaves the structured
residual below the practical level on every signal is named even below ``EXPLAIN_MIN``
(``_settles``): the rest is base mismatch that does not change what the simulator is good
for; what the effect removed did.

When the calibration took a tolerance the best effect trades off against to its bound and
the effect's own fit moved it off (``diagnose.calibration_absorbed``), the bound stood in
for the effect: the effect is judged against the simulator with its own tolerances and
without it (``against``), not against the calibrated one that had soaked part of it up.
A 400-700 N Coulomb friction removed 0.010-0.019 NRMSE from the structured gap of a
simulator whose viscous friction sat at +30 %, 0.022-0.036 from its own tolerances.
When the best is not named, a runner-up the calibration absorbed that does as well as the
calibrated simulator is judged that way too (``_absorbed_runner``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.fit.candidates import Candidate
from monitor.gap.fit.score import SegmentSums, gap, reduction
from monitor.gap.judge import basemis
from monitor.gap.judge.consistency import Worse, worse_signal
from monitor.gap.judge.shrink import boot_gap, boot_mse, boot_reduction

#: ``none``: held-out mean squared residual below this multiple of the noise floor on
#: every signal (a perfect simulator sits at 1).
NONE_RATIO = 2.0
#: Below this multiple on every signal, a gap that no effect explains significantly is
#: still ``none`` (not ``unexplained``): it is what a tolerance calibration leaves on a
#: healthy machine of the type.
MARGINAL_RATIO = 4.0
#: An effect must remove at least this share of the held-out gap to be named ...
EXPLAIN_MIN = 0.5
#: ... and its gain must be positive in at least this share of bootstrap resamples.
SIGNIFICANT = 0.95
#: A pair is kept when it removes this share of what the best single effect leaves ...
PAIR_GAIN = 0.3
#: ... and at least this share of the whole gap (a formulation mismatch of the first
#: effect leaves a small remainder that any second effect can nibble at).
PAIR_MATERIAL = 0.05
#: Runners-up (by rank) each tried as the best single effect's partner.
PAIR_POOL = 3
#: Not paired: fitted in closed form alone (``sensorcal.py``).
SENSOR_ONLY = "sensor_calibration"


@dataclass
class Decision:
    verdict: str
    also: str | None
    chosen: Candidate | None
    confidence: float
    #: The best effect was not named because it made this signal clearly worse.
    traded: tuple[str, Worse] | None = None


def within_noise(sums: SegmentSums, floor: np.ndarray, ratio: float = NONE_RATIO) -> bool:
    """Every signal's held-out mean squared residual within ``ratio`` x the noise."""
    return bool(np.all(sums.mse() < ratio * np.maximum(floor, 1e-12)))


def boot_gain(before: SegmentSums, after: SegmentSums, idx: np.ndarray, floor: np.ndarray):
    """Gap of ``before`` minus gap of ``after`` in each bootstrap resample."""
    return boot_gap(before, idx, floor) - boot_gap(after, idx, floor)


def gain_share(before: SegmentSums, after: SegmentSums, idx: np.ndarray, floor: np.ndarray):
    """Share of bootstrap resamples in which ``after`` has the smaller gap than ``before``."""
    return float(np.mean(boot_gain(before, after, idx, floor) > 0))


def explains(best: Candidate, gain: np.ndarray, removed: float | None = None) -> bool:
    """The best single effect removes at least ``EXPLAIN_MIN`` of the held-out gap
    (``removed``: of the gap of the simulator it is judged against; default: its reduction
    from the calibrated one) and gains over that simulator (``gain``: ``boot_gain`` from it
    to the best) in at least ``SIGNIFICANT`` of the bootstrap resamples."""
    share = best.heldout_reduction if removed is None else removed
    return bool(share >= EXPLAIN_MIN and np.mean(gain > 0) >= SIGNIFICANT)


def trades_signals(
    best: Candidate, before: SegmentSums, after: SegmentSums, idx: np.ndarray, floor: np.ndarray
) -> Worse | None:
    """The signal a physical effect makes clearly worse (``consistency.py``); None for a
    sensor calibration, which its own check judges (``sensorphysics.py``)."""
    if best.effects[0].name == SENSOR_ONLY:
        return None
    return worse_signal(before, after, idx, floor, SIGNIFICANT)


def whole_gap(c: Candidate) -> float:
    """The calibrated simulator's held-out gap, from what ``c`` leaves and removes."""
    return c.heldout_gap / max(1.0 - c.heldout_reduction, 1e-12)


def pair_plan(
    singles: list[Candidate],
    best_sums: SegmentSums,
    floor: np.ndarray,
    nominal: SegmentSums,
    idx: np.ndarray,
) -> list[tuple[str, str]]:
    """Name pairs worth fitting when the best single explains the gap (``explains``) and
    leaves a gap clearly above the noise: the best with each of the next few.  A pair's
    larger effect is the best single (a pair without it would have to beat it from two
    weaker ones), and the partner need not remove anything alone: friction under a lever
    load that the calibration's viscous friction half absorbs does not.  When the best does
    not explain the gap, ``decide`` never looks at a pair (the verdict is ``unexplained``,
    ``none`` or the best on the structured gap alone), so none is fitted: three pair fits
    were a fifth of an ``unexplained`` diagnosis's CPU.  Nor when the best leaves less than
    ``PAIR_MATERIAL`` of the gap: a pair cannot remove more than what is left (the gap is
    not negative), so none could be named."""
    if within_noise(best_sums, floor) or not singles:
        return []
    best = singles[0].effects[0].name
    if best == SENSOR_ONLY or not explains(singles[0], boot_gain(nominal, best_sums, idx, floor)):
        return []
    if trades_signals(singles[0], nominal, best_sums, idx, floor) is not None:
        return []  # not named (``decide``), so no pair either
    if singles[0].heldout_gap < PAIR_MATERIAL * whole_gap(singles[0]):
        return []
    # A sensor calibration is fitted in closed form on its own, never inside a pair.
    others = [c for c in singles[1:] if c.effects[0].name != SENSOR_ONLY]
    return [(best, c.effects[0].name) for c in others[:PAIR_POOL]]


def decide(
    noise_only: bool,
    singles: list[Candidate],
    pairs: list[Candidate],
    sums: dict[str, SegmentSums],
    nominal: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
    structured: tuple[dict[str, SegmentSums], SegmentSums] | None = None,
    against: dict[str, tuple[SegmentSums, SegmentSums]] | None = None,
) -> Decision:
    """Verdict, second effect, the chosen candidate and a bootstrap confidence (0..1).

    ``structured``: the smoothed sums per candidate name and of the calibrated simulator
    (None: judge the whole gap only); ``against``: per candidate name, the whole and
    smoothed sums of the simulator it is judged against instead of the calibrated one (the
    calibration absorbed it: see the module's docstring)."""
    if noise_only:
        # Share of resamples in which every signal stays within the noise band.
        conf = float(np.mean(np.all(boot_mse(nominal, idx) < NONE_RATIO * floor, axis=1)))
        return Decision("none", None, None, conf)
    if not singles:
        # Every candidate was ruled out (``lagcheck.py`` withdrew the only one of a reduced
        # list): nothing in the catalogue explains the gap.
        return Decision("unexplained", None, None, 1.0)
    best = singles[0]
    # The simulator the best is judged against: the calibrated one, unless it absorbed it.
    before, judged = nominal, structured
    if against is not None and best.name in against:
        before, before_s = against[best.name]
        judged = None if structured is None else (structured[0], before_s)
    red_b = boot_reduction(before, sums[best.name], idx, floor)
    gain_b = boot_gain(before, sums[best.name], idx, floor)
    named, worse, settled = _best_named(best, before, judged, sums, idx, floor, gain_b)
    if settled is not None:
        return settled
    traded = (best.effects[0].name, worse) if worse is not None else None
    if not named or worse is not None:
        if against:
            absorbed = _absorbed_runner(singles[1:], sums, nominal, idx, floor, structured, against)
            if absorbed is not None:
                return absorbed
        return not_named(nominal, idx, floor, structured, red_b, worse, traded)
    return _named(best, singles, pairs, sums, nominal, idx, floor, (red_b, gain_b))


def _best_named(
    best: Candidate,
    before: SegmentSums,
    judged: tuple[dict[str, SegmentSums], SegmentSums] | None,
    sums: dict[str, SegmentSums],
    idx: np.ndarray,
    floor: np.ndarray,
    gain_b: np.ndarray,
) -> tuple[bool, Worse | None, Decision | None]:
    """Whether the best explains the gap (against ``before``), the signal it makes clearly
    worse if it would be named, and the decision when its structured part settles it."""
    # Either way, an effect whose own structured part is below the practical level is not
    # named: a modest share of a healthy machine's base mismatch looks like that.
    large = _practical(best, judged, floor)
    named = large and explains(best, gain_b, reduction(gap(before.mse(), floor), best.heldout_gap))
    # Whichever way it would be named, an effect that trades one signal for the others is
    # not the machine's physics.
    worse = trades_signals(best, before, sums[best.name], idx, floor) if named else None
    if not named and large and judged is not None:
        s_conf = _structured_share(best, judged, idx, floor)
        if s_conf is None:
            s_conf = _settles(best, judged, gain_b, idx, floor)
        if s_conf is not None:
            smooth, before_s = judged
            floor_s = basemis.smoothed_floor(floor)
            worse = trades_signals(best, before, sums[best.name], idx, floor) or trades_signals(
                best, before_s, smooth[best.name], idx, floor_s
            )
            if worse is None:
                return named, worse, Decision(best.effects[0].name, None, best, s_conf)
    return named, worse, None


def not_named(
    nominal: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
    structured: tuple[dict[str, SegmentSums], SegmentSums] | None,
    red_b: np.ndarray,
    worse: Worse | None,
    traded: tuple[str, Worse] | None,
) -> Decision:
    """``none`` or ``unexplained`` when the best effect is not named."""
    if structured is not None:
        # What is left is base mismatch and a structured part too small to matter, or
        # not clearly larger: ``unexplained`` needs the structured part above the
        # practical level on some signal in ``SIGNIFICANT`` of the resamples, as an
        # effect needs its gain.
        floor_s = basemis.smoothed_floor(floor)
        small = basemis.small_share(structured[1], idx, floor_s)
        if basemis.practically_small(structured[1], floor_s) or small > 1 - SIGNIFICANT:
            return Decision("none", None, None, small, traded)
    if within_noise(nominal, floor, MARGINAL_RATIO):
        conf = np.all(boot_mse(nominal, idx) < MARGINAL_RATIO * floor, axis=1)
        return Decision("none", None, None, float(np.mean(conf)), traded)
    # Unexplained: the best does not explain the gap in the resample, or (when it traded
    # signals) the signal it makes worse grows in the resample.
    conf = worse.share if worse is not None else float(np.mean(red_b < EXPLAIN_MIN))
    return Decision("unexplained", None, None, conf, traded)


def _named(
    best: Candidate,
    singles: list[Candidate],
    pairs: list[Candidate],
    sums: dict[str, SegmentSums],
    nominal: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
    boot: tuple[np.ndarray, np.ndarray],
) -> Decision:
    """The best effect named, or a pair of it and another that clearly does better; with
    ``boot`` the best's bootstrap reduction and gain."""
    red_b, gain_b = boot
    gap0 = whole_gap(best)
    good = [
        p
        for p in pairs
        if p.heldout_gap <= (1 - PAIR_GAIN) * best.heldout_gap
        and best.heldout_gap - p.heldout_gap >= PAIR_MATERIAL * gap0
        and gain_share(sums[best.name], sums[p.name], idx, floor) >= SIGNIFICANT
    ]
    if good:
        pair = min(good, key=lambda p: p.criterion)
        # The larger effect: the one that removes more of the gap alone.
        alone = {c.effects[0].name: c.heldout_reduction for c in singles}
        first, second = sorted(
            (e.name for e in pair.effects), key=lambda n: alone.get(n, -np.inf), reverse=True
        )
        red_p = boot_reduction(nominal, sums[pair.name], idx, floor)
        wins = (red_p >= EXPLAIN_MIN) & (
            boot_gap(sums[pair.name], idx, floor) < boot_gap(sums[best.name], idx, floor)
        )
        return Decision(first, second, pair, float(np.mean(wins)))
    # Confidence: the effect explains the gap, gains over the calibrated simulator and beats
    # the runner-up in the resample.
    wins = (red_b >= EXPLAIN_MIN) & (gain_b > 0)
    if len(singles) > 1:
        runner = sums[singles[1].name]
        wins &= boot_gap(sums[best.name], idx, floor) < boot_gap(runner, idx, floor)
    return Decision(best.effects[0].name, None, best, float(np.mean(wins)))


def _absorbed_runner(
    rest: list[Candidate],
    sums: dict[str, SegmentSums],
    nominal: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
    structured: tuple[dict[str, SegmentSums], SegmentSums] | None,
    against: dict[str, tuple[SegmentSums, SegmentSums]],
) -> Decision | None:
    """When the best is not named: the first runner-up the calibration absorbed that does
    as well as the calibrated simulator (not clearly worse: its gain positive in more than
    ``1 - SIGNIFICANT`` of the resamples) and is named against its own tolerances.  A
    calibration that took viscous friction to its bound can leave a 400 N friction with
    nothing to add (ranked fourth, -0.7 % of the held-out gap) while against its own
    tolerances it removes 54 %: the bound, not the machine, made the tie."""
    for c in rest:
        if (
            c.name not in against
            or gain_share(nominal, sums[c.name], idx, floor) <= 1 - SIGNIFICANT
        ):
            continue
        d = decide(False, [c], [], sums, nominal, idx, floor, structured, against)
        if d.chosen is not None:
            return d
    return None


def _practical(
    best: Candidate,
    structured: tuple[dict[str, SegmentSums], SegmentSums] | None,
    floor: np.ndarray,
) -> bool:
    """What ``best`` removes from the structured residual, summed over the signals, reaches
    the practical level (``basemis.removes_practical``); True when not judged (no smoothed
    sums)."""
    if structured is None or best.name not in structured[0]:
        return True
    smooth, nominal_s = structured
    return basemis.removes_practical(nominal_s, smooth[best.name], basemis.smoothed_floor(floor))


def _settles(
    best: Candidate,
    structured: tuple[dict[str, SegmentSums], SegmentSums],
    gain: np.ndarray,
    idx: np.ndarray,
    floor: np.ndarray,
) -> float | None:
    """Confidence that ``best`` leaves nothing that matters (None: it does not).

    Named when (beside removing a practical amount, ``_practical``) its gain is significant
    and it leaves the structured residual below the practical level on every signal, even
    if that was less than ``EXPLAIN_MIN`` of the gap: what is left does not change what
    the simulator is good for, what it removed did.  Under the other team's base mismatch
    a 360-600 N Coulomb friction removed 47-50 % of the structured gap of the simulator at
    its own tolerances."""
    smooth, _ = structured
    if best.name not in smooth or np.mean(gain > 0) < SIGNIFICANT:
        return None
    floor_s = basemis.smoothed_floor(floor)
    if not basemis.practically_small(smooth[best.name], floor_s):
        return None
    small = basemis.small_each(smooth[best.name], idx, floor_s)
    return float(np.mean(small & (gain > 0)))


def _structured_share(
    best: Candidate,
    structured: tuple[dict[str, SegmentSums], SegmentSums],
    idx: np.ndarray,
    floor: np.ndarray,
) -> float | None:
    """Confidence that ``best`` explains the structured gap (None: it does not).

    Named when it removes at least ``EXPLAIN_MIN`` of the calibrated simulator's structured
    gap and its structured gain is significant under the block bootstrap."""
    smooth, nominal_s = structured
    if best.name not in smooth:
        return None
    floor_s = basemis.smoothed_floor(floor)
    after = smooth[best.name]
    red = reduction(gap(nominal_s.mse(), floor_s), gap(after.mse(), floor_s))
    gain = boot_gain(nominal_s, after, idx, floor_s)
    if red < EXPLAIN_MIN or np.mean(gain > 0) < SIGNIFICANT:
        return None
    red_b = boot_reduction(nominal_s, after, idx, floor_s)
    return float(np.mean((red_b >= EXPLAIN_MIN) & (gain > 0)))
