"""Twin runs: how far a fault run's fault moved the signals, in the detector's own units.

For a fault run of ``monitor eval-sim`` the same commands are simulated noise-free with and
without the fault; one plant run gives both the noisy recording the detector scores and the
noise-free faulty twin, so only the healthy twin costs a second plant run.  The difference of
the model's outputs, z-scored as the model scales them, is the residual a detector with a
perfect healthy model of the plant and noise-free sensors would see.  Its J (eq. 9, the
model's window, over the samples the detector judged) divided by eps0 is ``fault_j_ratio``:

- below 1, the fault moved the signals less, in J, than the threshold lets healthy residuals
  move them: the duty cycle did not *exercise* the fault enough for this threshold;
- at or above 1, a detector could see it; whether this one does depends on its predictor
  (a one-step predictor fed the measured outputs follows a level offset it predicts as an
  increment, see docs/explanation/evaluation.md).

It ignores the model's own healthy error (which adds to J on top of the fault's) and the
sensor noise, so it is neither an upper nor a lower bound on the detector's J.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.detection.alarm import regimes_of
from monitor.detection.offline import residual_series
from monitor.io.recording import Recording
from monitor.model.modelfile import MonitorModel
from monitor.model.residual import window_j
from monitor.model.spec import table
from monitor.model.statistic import active
from monitor.sim.faults import Fault
from monitor.sim.machine import MachineParams
from monitor.sim.simulate import run_plant, sense, simulate

#: Names of ``regimes_of``'s codes (spool command beyond +-5 %: raise / lower, else hold).
REGIME_NAMES = ("hold", "raise", "lower")


@dataclass(frozen=True)
class Twins:
    """One fault run's recordings on the same commands."""

    noisy: Recording  # what the detector scores: exactly simulate(..., seed=seed)
    faulty: Recording  # noise-free, with the fault
    healthy: Recording  # noise-free, without it


def simulate_twins(
    commands: Recording, machine: MachineParams, faults: Sequence[Fault], seed: int | None
) -> Twins:
    """The noisy run and its two noise-free twins (two plant runs, not three)."""
    trace = run_plant(commands, machine, list(faults))
    noisy = sense(commands, trace, machine, list(faults), seed=seed)
    faulty = sense(commands, trace, machine, list(faults), seed=None)
    healthy = simulate(commands, machine, [], seed=None)
    return Twins(noisy, faulty, healthy)


def twin_residual(model: MonitorModel, twins: Twins) -> np.ndarray:
    """(samples, outputs): healthy minus faulty twin in the model's z-units, the sign of a
    residual (e = y_hat - y) whose prediction is the healthy plant; clipped as the
    detector clips its residuals (``residual_clip``)."""
    outs = model.spec.outputs
    zf = model.normalizer.transform(table(twins.faulty, outs), outs)
    zh = model.normalizer.transform(table(twins.healthy, outs), outs)
    e = zh - zf
    if model.residual_clip is not None:
        bound = np.asarray(model.residual_clip)
        e = np.clip(e, -bound, bound)
    return e


def fault_view(
    model: MonitorModel,
    twins: Twins,
    onset_s: float,
    judged: np.ndarray | None = None,
) -> dict[str, Any]:
    """The fault's own J over a run, against the model's threshold eps0.

    ``judged``: samples the detector judged on the noisy run (its residual finite); the
    others pause the window here too, so J sees the samples the detector saw.  Keys:
    ``fault_j_ratio`` (max fault J at or after ``onset_s`` / eps0; None before any full
    window), ``fault_j_above_eps0_s`` (seconds of fault J >= eps0), ``fault_signal_share``
    and ``fault_regime_share`` (shares of the squared difference after the onset by output and
    by hold / raise / lower; None when the fault changed nothing).
    """
    e = twin_residual(model, twins)
    if judged is not None:
        e[~np.asarray(judged, dtype=bool)] = np.nan
    t = twins.faulty.t - twins.faulty.t[0]
    after = t >= onset_s - 1e-9
    period_s = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    j = window_j(e, model.window_n)
    j_after = j[after & np.isfinite(j)]
    out: dict[str, Any] = {
        "fault_j_ratio": _peak_ratio(j, after, model.eps0),
        "fault_j_above_eps0_s": round(float(np.sum(j_after >= model.eps0)) * period_s, 2),
    }
    # No fault B here: B's scales are those of the one-step residual, which follows a level
    # offset of PA and PB (predicted as increments); applied to the outputs' difference they
    # read a small trapped-pressure change as tens of b0 (docs/explanation/evaluation.md).
    spool = twins.faulty["SpoolCmd"]
    rows = after & np.isfinite(e).all(axis=1)
    sq = e[rows] ** 2
    total = float(sq.sum())
    if total > 0:
        by_signal = sq.sum(axis=0) / total
        regimes = regimes_of(spool)[rows]
        by_regime = [float(sq[regimes == k].sum()) / total for k in range(len(REGIME_NAMES))]
        out["fault_signal_share"] = {
            name: round(float(v), 3) for name, v in zip(model.spec.outputs, by_signal, strict=True)
        }
        out["fault_regime_share"] = {
            name: round(v, 3) for name, v in zip(REGIME_NAMES, by_regime, strict=True)
        }
    else:
        out["fault_signal_share"] = out["fault_regime_share"] = None
    return out


def predictor_view(
    model: MonitorModel,
    twins: Twins,
    onset_s: float,
    judged: np.ndarray,
    horizon: int | None = None,
) -> dict[str, Any]:
    """The fault as this model's predictor passes it on: each statistic of the model on the
    residual on the noise-free faulty twin minus the residual on the healthy twin (two
    predictions).

    Unlike ``fault_view`` this sees what the predictor does with the fault (a level offset
    of an output predicted as an increment mostly vanishes; changed inputs can move another
    output's prediction), so the scales of B, L and H fit it.  Keys:
    ``fault_residual_<name>_ratio`` per statistic (``j``: max J / eps0 at or after
    ``onset_s``, ``b``: max B / b0, ...; None without a full window, ``b`` None without a
    bias model) and ``fault_residual_level_ratio``, the largest: the alarm level the fault
    alone would give this detector.
    """
    ok = np.asarray(judged, dtype=bool)
    _, ef = residual_series(model, twins.faulty, ~ok, horizon)
    _, eh = residual_series(model, twins.healthy, ~ok, horizon)
    d = ef - eh
    d[~ok] = np.nan
    t = twins.faulty.t - twins.faulty.t[0]
    after = t >= onset_s - 1e-9
    out: dict[str, Any] = {}
    for stat in active(model):  # J, B, L, H, ...: each against its threshold
        threshold = stat.threshold_
        if threshold == threshold:
            peak = _peak_ratio(stat.series(d, twins.faulty), after, threshold)
            out[f"fault_residual_{stat.name.lower()}_ratio"] = peak
    out.setdefault("fault_residual_b_ratio", None)  # the key stays without B
    ratios = [v for v in out.values() if v is not None]
    out["fault_residual_level_ratio"] = max(ratios) if ratios else None
    return out


def _peak_ratio(series: np.ndarray, after: np.ndarray, threshold: float) -> float | None:
    """Largest finite value where ``after`` over ``threshold``; None if there is none."""
    v = series[after & np.isfinite(series)]
    return round(float(v.max()) / threshold, 4) if v.size else None
