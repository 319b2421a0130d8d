"""The summary ``monitor detect`` writes for a recording (docs/reference/events.md): the
alarm and its episodes, each statistic's largest value, the gating's findings and the
verdict, from the per-sample results of ``monitor.detection.offline``."""

from __future__ import annotations

from typing import Any

import numpy as np

from monitor.detection.alarm import State
from monitor.detection.episodes import Alarms
from monitor.detection.gating import Gate, GateSeries
from monitor.detection.opstate import OpState
from monitor.detection.outofrange import describe, out_of_range_values
from monitor.detection.plausibility import finding
from monitor.detection.verdict import judged_mask, verdict
from monitor.io.recording import Recording
from monitor.model.machinecard import COMMISSION
from monitor.model.modelfile import MonitorModel
from monitor.model.residual import J, on_stops
from monitor.model.statistic import statistic_keys, statistics_entries
from monitor.signals import source_signal


def detection_summary(
    model: MonitorModel,
    rec: Recording,
    gate: Gate,
    g: GateSeries,
    alarms: Alarms,
    series: dict[str, np.ndarray],
    level: np.ndarray,
    horizon: int | None,
    missing: np.ndarray,
    reference: str | None = None,
) -> dict[str, Any]:
    """The summary's keys, in the order the file shows them (``reference``: why the model
    is another machine's, ``machinecard.reference_reason``)."""
    states = alarms.states
    summary = {
        "alarm": alarms.first_alarm_t is not None,
        "first_alarm_t": alarms.first_alarm_t,
        "alarm_episodes": alarms.episodes,
        "fault": alarms.first_fault,
        "sensor_fault": bool(np.any(states == State.SENSOR_FAULT)),
        # Each statistic's largest value and threshold (null for one the model lacks), and
        # the largest alarm level, 1 being the alarm threshold.
        **statistic_keys(model, series),
        "max_level": float(np.nanmax(level)) if np.isfinite(level).any() else None,
        "threshold_rule": model.threshold.rule,
        "window_n": model.window_n,
        "horizon": horizon or model.spec.horizon,
        "samples": len(rec),
        "inactive_fraction": float(np.mean(states == State.INACTIVE)),
        "sensor_fault_fraction": float(np.mean(states == State.SENSOR_FAULT)),
        **gating_summary(rec, gate, g),
        "source": rec.source,
        "reference_model": reference is not None,
        "withheld": _withheld(reference, alarms, level),
    }
    period = float(np.median(np.diff(rec.t))) if len(rec) > 1 else 0.01
    summary["out_of_range_values"] = out_of_range_values(
        gate.validity_values(rec), g.oor, gate.validity
    )
    summary["judged_beyond_oil_s"] = beyond_oil_seconds(states, series["J"], level, period)
    summary["verdict"], summary["judged_s"], summary["not_judged_why"] = verdict(
        summary,
        states,
        series["J"],
        g.op_state,
        g.oor,
        ~np.asarray(missing.any(axis=1)),
        rec["EngineSpeed"],
        model.window_n,
        period,
        describe(summary["out_of_range_values"]),
    )
    summary["on_stop_not_judged_s"] = on_stop_seconds(model, rec, states, period)
    summary["rejected"] = rejected_counts(rec)
    summary["statistics"] = statistics_entries(model)
    names = tuple(map(source_signal, model.spec.variables))
    summary["sensor_checks"] += stale_checks(rec, states, g.check, missing, names)
    return summary


def beyond_oil_seconds(
    states: np.ndarray, j: np.ndarray, level: np.ndarray, period_s: float
) -> float:
    """Seconds judged where J was not: oil beyond the envelope, judged by the statistics
    with an oil range of their own alone (``Statistic.beyond_oil``: F); not in ``judged_s``
    (``monitor.detection.verdict``)."""
    alone = judged_mask(states, level) & ~np.isfinite(j)
    return round(float(alone.sum()) * period_s, 3)


def on_stop_seconds(
    model: MonitorModel, rec: Recording, states: np.ndarray, period_s: float
) -> float | None:
    """Seconds the monitor ran while the rod settled on an end stop, which J left out (not
    judged, never healthy); None when the model's J judges every sample."""
    if not J.get(model).stops:
        return None
    running = (states == State.NORMAL) | (states == State.FAULT)
    return round(float(np.sum(running & on_stops(rec))) * period_s, 3)


def _withheld(reference: str | None, alarms: Alarms, level: np.ndarray) -> dict[str, Any] | None:
    """The summary's ``withheld``: null unless a reference model's alarm was withheld, then
    when the first would have been raised, how many, the largest level, and why."""
    if reference is None or not alarms.withheld_t:
        return None
    top = float(np.nanmax(level))
    why = (
        f"{reference}: a level of {top:.3g} (1 = alarm) does not tell a fault from this "
        f"machine's difference from the model's machine; {COMMISSION}"
    )
    return {
        "first_t": alarms.withheld_t[0],
        "episodes": len(alarms.withheld_t),
        "max_level": top,
        "reason": why,
    }


def stale_checks(
    rec: Recording,
    states: np.ndarray,
    check: np.ndarray,
    missing: np.ndarray,
    names: tuple[str, ...],
) -> list[dict[str, Any]]:
    """Sensor faults from missing data (frames stale, rejected or never sent), per signal."""
    t = rec.t - rec.t[0]
    out = []
    mine = (states == State.SENSOR_FAULT) & (check == 0)
    for k, name in enumerate(names):
        rows = np.flatnonzero(mine & missing[:, k])
        if rows.size:
            out.append(
                {
                    "sensor": name,
                    "check": "stale",
                    "first_t": round(float(t[rows[0]]), 6),
                    "samples": int(rows.size),
                }
            )
    return out


def rejected_counts(rec: Recording) -> dict[str, dict[str, int]]:
    """Frames rejected per message and reason (dlc, crc, range, counter_jump) while reading
    a candump log; empty for a CSV."""
    counts = rec.meta.get("counts")
    if not isinstance(counts, dict):
        return {}
    return {k: dict(v) for k, v in counts.get("rejected_by_message", {}).items()}


def gating_summary(rec: Recording, gate: Gate, g: GateSeries) -> dict[str, Any]:
    """Summary keys of the gating: time per operating state, out-of-range samples per
    signal, sensor findings with their first time, and the envelope's coverage."""
    t = rec.t - rec.t[0]
    period = float(np.median(np.diff(rec.t))) if len(rec) > 1 else 0.01
    op_s = {s.label: round(float(np.sum(g.op_state == s)) * period, 3) for s in OpState}
    oor = {
        name: int(np.sum(g.oor == k))
        for k, name in enumerate(gate.validity.signals)
        if np.any(g.oor == k)
    }
    idx = np.flatnonzero(g.check != 0)
    codes = g.check[idx].astype(np.int64) * 256 + g.sensor[idx]
    uniq, first, count = np.unique(codes, return_index=True, return_counts=True)
    checks = []
    for code, k, c in sorted(zip(uniq, first, count, strict=True), key=lambda u: u[1]):
        sensor, name = finding(int(code) // 256, int(code) % 256)
        checks.append(
            {
                "sensor": sensor,
                "check": name,
                "first_t": round(float(t[idx[k]]), 6),
                "samples": int(c),
            }
        )
    normal = g.op_state == OpState.NORMAL
    env = gate.validity.envelope
    return {
        "op_state_s": op_s,
        "out_of_range_samples": int(np.sum(g.oor >= 0)),
        "out_of_range_s": round(float(np.sum(g.oor >= 0)) * period, 3),
        "out_of_range_signals": oor,
        "sensor_checks": checks,
        "envelope": None if env is None else env.source,
        "sparse_coverage": gate.validity.sparse_shares(gate.validity_values(rec), normal),
    }
