"""`monitor train`'s statistics: every member of the family fitted on the held-out residuals.

Each member says from the settings whether it is asked for (``Statistic.configure``), fits its
scales and threshold on held-out normal data (``Statistic.fit``), or is off with the reason
(data too short to support it); the model file keeps the note and what each threshold rests
on.  A reference model of the machine type floors the thresholds that carry over to another
machine of it (J's, B's): see :func:`floor_thresholds`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.model.modelfile import MonitorModel
from monitor.model.residual import on_stops
from monitor.model.spec import DGRNNSpec
from monitor.model.statistic import HeldOut, Statistic, registry
from monitor.model.threshold import ThresholdRule
from monitor.training.support import earned, rests_on_one_event, support_line

Progress = Callable[[str], None]


def fit_statistics(
    model: MonitorModel, held: HeldOut, settings: Any, say: Progress
) -> tuple[dict[str, str], dict[str, Any]]:
    """Every member as ``settings`` (a ``TrainConfig``) ask, into ``model``: J always (its
    failure is the training's), the others off with the reason when the held-out data
    cannot support them (too short, too few independent windows, one session, or a
    threshold that does not hold from one half of the held-out data to the other:
    :func:`earned`; ``--support-check off`` keeps them).  Returns the
    notes ("on" or "off...") by member key and what each threshold rests on by member name."""
    rule: ThresholdRule = settings.thresholds.rule
    notes: dict[str, str] = {}
    support: dict[str, Any] = {}
    on: set[str] = set()
    for cls in registry():
        stat = cls.configure(settings, held.outputs, on)
        if isinstance(stat, str):
            if cls.asked_by and getattr(settings.statistics, cls.asked_by):
                say(f"  {cls.title} {stat}")
            cls.put(model, None)
            notes[cls.key] = stat
            continue
        data = own_data(held) if cls.own_held_out else held
        try:
            stat.fit(data, rule)
        except InputFileError as exc:
            if not cls.optional:
                raise
            say(f"  {cls.title} off: {exc}")  # short commissioning data: said, and left out
            cls.put(model, None)
            notes[cls.key] = f"off: {exc}"
            continue
        event = rests_on_one_event(stat, data)
        why = earned(stat, data, rule)
        whys = [w for w in (event, why) if w is not None]
        support[cls.name] = stat.support_
        if whys and cls.optional and settings.statistics.support_check:
            for w in whys:
                say(f"  {cls.title} off: {w}")
            cls.put(model, None)
            notes[cls.key] = "off: " + "; ".join(whys)
            continue
        cls.put(model, stat.params_)
        on.add(cls.name)
        notes[cls.key] = "on" if not whys else "on, thinly supported: " + "; ".join(whys)
        say(said(stat, data, rule))
        say(support_line(stat))
        for w in whys:  # J stays on (the level rests on it), with the warning
            say(f"  warning: {cls.title}'s threshold is thinly supported: {w}")
    return notes, support


def own_data(held: HeldOut) -> HeldOut:
    """What a member that holds out its own data (``Statistic.own_held_out``) is fitted on:
    every normal recording given to training, without the DGRNN's residuals (none there)."""
    every = list(held.every) or list(held.recordings)
    return HeldOut(
        [np.zeros((len(r), 0)) for r in every],
        every,
        held.outputs,
        every,
        "its own: every normal recording, cross-fitted",
    )


def said(stat: Statistic, held: HeldOut, rule: ThresholdRule) -> str:
    """One line on a fitted statistic for ``monitor train``'s progress."""
    if not stat.optional:  # J: J0 and eps0 (eq. 10)
        kind = "cross-fitted" if held.validation.startswith("cross") else "held-out"
        return (
            f"  J0 {stat.params_.j0:.4g} ({rule.rule} of J on {len(held.recordings)} "
            f"{kind} part(s)), eps0 {stat.threshold_:.4g}: {rule.describe()}{_stops(stat, held)}"
        )
    floor = getattr(stat, "support_", {}).get("floor")  # a member's own least threshold
    return (
        f"  {stat.title} over {stat.window_n / 100:g} s, {stat.threshold_key} "
        f"{stat.threshold_:.4g}: {rule.describe()}" + (f", floored: {floor}" if floor else "")
    )


def _stops(stat: Statistic, held: HeldOut) -> str:
    """What J left out of its held-out data: the samples settling on an end stop."""
    if not getattr(stat.params_, "stops", False):
        return ""
    left = sum(int(on_stops(r).sum()) for r in held.recordings) * 0.01
    return f"; {left:.1f} s settling on an end stop left out (not judged; --stops-in-j judge)"


def check_reference(reference: MonitorModel, spec: DGRNNSpec, window_n: int) -> None:
    """ConfigError naming both when ``reference`` is not a model of this spec and window."""
    if reference.spec == spec and reference.window_n == window_n:
        return

    def what(s: DGRNNSpec, n: int) -> str:
        return (
            f"{'/'.join(s.outputs)} from {'/'.join(s.variables)}, horizon {s.horizon}, J window {n}"
        )

    raise ConfigError(
        f"the reference model ({what(reference.spec, reference.window_n)}) does not match the "
        f"model to train ({what(spec, window_n)}): train with the reference's preset, "
        "--horizon and --window"
    )


def floor_thresholds(model: MonitorModel, reference: MonitorModel) -> str:
    """Raise each threshold that carries over (eps0, b0) to at least the reference model's;
    what was done, in one line.

    Minutes of commissioning cannot show the tail of hours: on simulated machines the
    largest B of 20 cross-fitted minutes (3.5 to 9) stayed far below what 2 hours of the
    same duty cycle reach (17), so thresholds set on it alone raised false alarms.  B is a
    standard score, so the reference's b0, set on hours of held-out data, carries over to
    another machine of the type; and a model fitted on minutes predicts no better than the
    reference fitted on hours, so the reference's eps0 is a lower bound for its J."""
    check_reference(reference, model.spec, model.window_n)
    notes = []
    for cls in registry():
        ours, theirs = cls.get(model), cls.get(reference)
        if not cls.carries_over or ours is None or theirs is None:
            continue
        own, ref = cls().use(ours), cls().use(theirs)
        if ref.threshold_ > own.threshold_:
            notes.append(f"{cls.threshold_key} {own.threshold_:.4g} -> {ref.threshold_:.4g}")
            cls.put(model, own.with_threshold(ref.threshold_))
    return ", ".join(notes) or "own thresholds already above the reference's"
