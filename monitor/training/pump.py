"""``monitor train --pump``: the shared pump's margin law learnt from the machine's own
normal operation, and the threshold its held-out data supports (``monitor.model.pumplaw``).

The law is fitted by least squares on the counted samples of the training recordings
(the pump rule's own choice: ``monitor.detection.pump.counted_samples``).  The threshold is
``factor`` x the largest |window mean residual| of the held-out recordings, as eps0 is
factor x the largest held-out J.  As for an optional statistic (``monitor.training.support``)
the threshold must rest on enough: at least ``MIN_BLOCKS`` independent (non-overlapping)
windows, held-out recordings of ``MIN_SESSIONS`` sessions, and a threshold set on one half
of the held-out sessions that the other half does not reach.  When it does not, the rule
is off (the file says why and what data would switch it on): unjudged, never healthy.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from monitor.detection.pump import PumpColumns, counted_samples, window_stats
from monitor.errors import InputFileError
from monitor.model.pumplaw import Counting, MarginLaw, PumpModel
from monitor.model.threshold import MIN_BLOCKS
from monitor.training.support import MIN_SESSIONS

#: threshold = FACTOR x the largest held-out |window mean residual| (eps0's factor).
FACTOR = 2.0


def fit_law(model: PumpModel, cols: PumpColumns, fits: Sequence[np.ndarray]) -> MarginLaw:
    """The law by least squares on the counted samples of ``fits`` (row arrays)."""
    s = np.vstack([counted_samples(model, cols, rows) for rows in fits])
    need = 2 * model.counting.window_n
    if len(s) < need:
        raise InputFileError(
            f"the training recordings hold {len(s) * 0.01:.0f} s of steady open flow (a "
            f"section open, spools steady, flow drawn); the pump's law needs {need * 0.01:g} s"
        )
    a = np.column_stack([s[:, 0], s[:, 1], np.ones(len(s))])
    coef, *_ = np.linalg.lstsq(a, s[:, 2], rcond=None)
    return MarginLaw(float(coef[0]), float(coef[1]), float(coef[2]))


def _peak(stats: Sequence[np.ndarray]) -> float:
    finite = [np.abs(x) for x in stats if x.size]
    return float(max(x.max() for x in finite)) if finite else float("nan")


def _transfer(stats: Sequence[np.ndarray], factor: float) -> float:
    """The worst ratio of one half's largest |statistic| to the threshold set on the other
    (sessions dealt alternately); NaN when a half has no window."""
    halves = (stats[0::2], stats[1::2])
    ratios = []
    for a, b in (halves, halves[::-1]):
        ta, pb = factor * _peak(a), _peak(b)
        if not (ta > 0 and pb == pb):
            return float("nan")
        ratios.append(pb / ta)
    return max(ratios)


def off_reason(support: dict[str, Any]) -> str | None:
    """Why the held-out data does not support a threshold (None: it does)."""
    n_eff, window_s = support["independent_windows"], support["window_s"]
    if n_eff < MIN_BLOCKS:
        return (
            f"its threshold would rest on {n_eff} independent windows of {window_s:g} s of "
            f"steady open flow, it needs {MIN_BLOCKS}: about "
            f"{(MIN_BLOCKS - n_eff) * window_s / 60 / max(support['counted_share'], 0.01):.0f}"
            " min more held-out normal work (--held-out) would switch it on"
        )
    if support["sessions"] < MIN_SESSIONS:
        return (
            "its threshold would rest on one recording (one session); held-out normal "
            f"recordings of at least {MIN_SESSIONS} sessions (--held-out) would switch it on"
        )
    ratio = support["transfer_ratio"]
    if ratio == ratio and ratio > 1.0:
        return (
            f"set on half of the held-out sessions it is reached {ratio:.3g} x by the other "
            "half: held-out normal work that spans the machine's conditions would switch it on"
        )
    return None


def fit_pump(
    fits: Sequence[np.ndarray],
    held: Sequence[np.ndarray],
    cols: PumpColumns,
    margin_bar: float,
    say: Callable[[str], None] = lambda _msg: None,
) -> PumpModel:
    """The pump model from ``fits`` and ``held`` (row arrays ``[t, *columns]`` of normal
    whole-machine recordings): the law, then the threshold and its support."""
    blank = PumpModel(MarginLaw(0.0, 0.0, 0.0), Counting(margin_bar), None)
    law = fit_law(blank, cols, fits)
    say(
        f"pump margin law: deficit = {law.flow_coef:.4f} bar per L/min x total flow + "
        f"{law.pp_coef:.5f} x PP {law.offset_bar:+.3f} bar"
    )
    model = replace(blank, law=law)
    judged = [window_stats(model, cols, rows) for rows in held]
    stats = [s for s, _ in judged]
    counted = sum(n for _, n in judged)
    window_n = model.counting.window_n
    hours = sum(float(r[-1, 0] - r[0, 0]) for r in held if len(r)) / 3600.0
    peak = _peak(stats)
    support = {
        "held_out_h": round(hours, 3),
        "sessions": len(held),
        "counted_s": round(counted * 0.01, 1),
        "counted_share": round(counted * 0.01 / max(hours * 3600.0, 1e-9), 3),
        "window_s": window_n * 0.01,
        "independent_windows": sum(n // window_n for _, n in judged),
        "held_out_max_bar": None if peak != peak else round(peak, 5),
        "transfer_ratio": round(_transfer(stats, FACTOR), 4),
    }
    why = off_reason(support)
    threshold = None if why is not None or not peak > 0 else round(FACTOR * peak, 5)
    say(
        f"  on {hours * 60:.1f} min held out ({support['counted_s']:g} s counted), "
        f"{support['independent_windows']} independent {window_n * 0.01:g} s windows, largest "
        f"|mean residual| {peak:.4f} bar; other half's peak {support['transfer_ratio']:.2g} x"
    )
    say(f"pump rule off: {why}" if threshold is None else f"pump threshold {threshold:.4f} bar")
    return replace(model, threshold_bar=threshold, off_reason=why, support=support)


def _cross_fitted(
    blank: PumpModel, cols: PumpColumns, recordings: Sequence[np.ndarray], folds: int
) -> list[list[tuple[np.ndarray, int]]]:
    """Each recording cut into ``folds`` pieces in time order, each piece's window
    statistics by a law fitted on every other piece (a piece whose others cannot fit a law
    is left out): per recording, its pieces' (statistics, counted samples)."""
    pieces = [np.array_split(rows, folds) for rows in recordings]
    out = []
    for i, parts in enumerate(pieces):
        judged = []
        for k, piece in enumerate(parts):
            others = [
                p for j, ps in enumerate(pieces) for m, p in enumerate(ps) if (j, m) != (i, k)
            ]
            try:
                law = fit_law(blank, cols, others)
            except InputFileError:
                continue
            judged.append(window_stats(replace(blank, law=law), cols, piece))
        out.append(judged)
    return out


def commission_pump(
    recordings: Sequence[np.ndarray], cols: PumpColumns, margin_bar: float, folds: int = 4
) -> PumpModel:
    """The pump model of one machine from its commissioning recordings alone (`monitor fleet
    run`), as its loops are commissioned (`monitor train --folds`): the law fitted on all of
    them, the threshold ``FACTOR`` x the largest |window mean residual| cross-fitted over
    ``folds`` pieces of each recording.  The support rule as for a loop's J, the statistic
    the pump's level rests on: too few independent windows of steady open flow and the rule
    is off (the pump unjudged, never healthy); one session, or halves (one recording: its
    cooler and warmer half) that do not transfer, keep it on with the reason noted
    (``support["warning"]``)."""
    blank = PumpModel(MarginLaw(0.0, 0.0, 0.0), Counting(margin_bar), None)
    try:
        law = fit_law(blank, cols, recordings)
    except InputFileError as exc:
        return replace(blank, off_reason=str(exc), support={"sessions": len(recordings)})
    judged = _cross_fitted(blank, cols, recordings, folds)
    window_n = blank.counting.window_n
    pieces = [s for rec in judged for s, _ in rec]
    # The transfer check's halves: the sessions, or one recording's cooler and warmer half.
    groups = [np.concatenate([s for s, _ in rec] or [np.zeros(0)]) for rec in judged]
    if len(judged) == 1:
        half = (len(judged[0]) + 1) // 2
        groups = [
            np.concatenate([s for s, _ in part] or [np.zeros(0)])
            for part in (judged[0][:half], judged[0][half:])
        ]
    counted = sum(n for rec in judged for _, n in rec)
    hours = sum(float(r[-1, 0] - r[0, 0]) for r in recordings if len(r)) / 3600.0
    peak = _peak(pieces)
    support: dict[str, Any] = {
        "held_out_h": round(hours, 3),
        "cross_fitted_folds": folds,
        "sessions": len(recordings),
        "counted_s": round(counted * 0.01, 1),
        "counted_share": round(counted * 0.01 / max(hours * 3600.0, 1e-9), 3),
        "window_s": window_n * 0.01,
        "independent_windows": sum(n // window_n for rec in judged for _, n in rec),
        "held_out_max_bar": None if peak != peak else round(peak, 5),
        "transfer_ratio": round(_transfer(groups, FACTOR), 4),
    }
    # The commissioning data are all there is: more of them, not --held-out, would help.
    said = (off_reason(support) or "").replace(" (--held-out)", "")
    why = said.replace("held-out normal", "commissioning").replace("recordings", "logs") or None
    if support["independent_windows"] < MIN_BLOCKS or not peak > 0:
        why = why or "no window of steady open flow in the commissioning data"
        return PumpModel(law, blank.counting, None, why, support)
    if why is not None:  # J's way: on, with what more data would support it
        support["warning"] = why.replace("would rest", "rests").replace(
            "switch it on", "support it"
        )
    return PumpModel(law, blank.counting, round(FACTOR * peak, 5), None, support)
