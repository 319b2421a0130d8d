"""Offline detection: a recording through the DGRNN, J(k+1), the threshold and the alarm machine.

The per-sample decisions are those of ``AlarmMachine``, the same object the live daemon
steps once per 100 Hz tick, so a recording gives the same events at a desk as on the bus.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.detection.alarm import AlarmConfig, Isolator, State, regimes_of
from monitor.detection.decision import Decider, event_record
from monitor.detection.gating import Gate, GateSeries, GatingConfig
from monitor.detection.opstate import OpState
from monitor.detection.outofrange import describe, out_of_range_values
from monitor.detection.plausibility import finding
from monitor.detection.verdict import verdict
from monitor.errors import InputFileError
from monitor.io.recording import Recording
from monitor.model.dgrnn import predict_series
from monitor.model.modelfile import MonitorModel
from monitor.model.spec import table
from monitor.model.statistic import active, level_series, statistic_keys, statistics_entries


@dataclass
class Detection:
    """Everything ``monitor detect`` reports for one recording."""

    t: np.ndarray
    y_hat: np.ndarray  # predicted outputs, physical units, columns = model outputs
    residual: np.ndarray  # e = y_hat - y in z-units (eq. 8); NaN where gated or missing
    j: np.ndarray  # J(k+1), eq. 9
    state: np.ndarray  # State per sample
    events: list[dict[str, Any]] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)
    gates: GateSeries | None = None  # operating state, sensor findings, out of range
    level: np.ndarray | None = None  # the largest statistic / its threshold: compared with 1
    #: Each statistic of the model per sample, by name (``J``, ``B``, ...; see
    #: ``monitor.model.statistic``); a statistic the model lacks has none.
    series: dict[str, np.ndarray] = field(default_factory=dict)
    # Each alarm episode, named once from the isolation votes over all of it (see _Run).
    episodes: list[dict[str, Any]] = field(default_factory=list)


def make_isolator(model: MonitorModel) -> Isolator | None:
    if not model.isolation_labels:
        return None
    return Isolator(
        model.isolation_labels,
        model.isolation_centroids,
        len(model.spec.outputs),
        model.isolation_min_similarity,
    )


def residual_series(
    model: MonitorModel,
    rec: Recording,
    gate: np.ndarray,
    horizon: int | None = None,
    exact: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """(y_hat in physical units, e in z-units); gated rows never feed a prediction.

    ``exact`` sums every GRNN pattern instead of those within the cut-off (see
    ``monitor.model.grnn_index``); tests use it to show both give the same decisions."""
    spec = model.spec
    z = model.normalizer.transform(table(rec, spec.variables), spec.variables)
    z[gate] = np.nan  # an engine-off or sensor-fault row must not seed a prediction
    yz = predict_series(model.dgrnn, z, horizon, exact)
    n_out = len(spec.outputs)
    e = yz - z[:, :n_out]
    if model.residual_clip is not None:
        # One-sample events the 100 Hz model cannot foresee (an end-stop impact) would
        # otherwise set J0 on their own; faults show as sustained residuals below the bound.
        bound = np.asarray(model.residual_clip)
        e = np.clip(e, -bound, bound)
    y_hat = model.normalizer.inverse_transform(yz, spec.outputs)
    return y_hat, e


def gated_residuals(
    model: MonitorModel,
    rec: Recording,
    min_engine_rpm: float,
    horizon: int | None = None,
    exact: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(y_hat, e, inactive, inputs_ok): residuals with engine-off and incomplete rows gated
    out (NaN), as both the detector and the training's J0 see them."""
    check_recording(model, rec, horizon)
    inactive = ~(rec["EngineSpeed"] >= min_engine_rpm)
    inputs_ok = np.all(np.isfinite(table(rec, model.spec.variables)), axis=1)
    y_hat, e = residual_series(model, rec, inactive | ~inputs_ok, horizon, exact)
    e[inactive | ~inputs_ok] = np.nan
    return y_hat, e, inactive, inputs_ok


def check_recording(model: MonitorModel, rec: Recording, horizon: int | None = None) -> None:
    spec = model.spec
    needed = (*spec.variables, "EngineSpeed")
    missing = [n for n in dict.fromkeys(needed) if not rec.has(n)]
    if missing:
        raise InputFileError(
            f"{rec.source}: the model needs signal(s) {', '.join(missing)}, which the "
            f"recording does not have (model signals: {', '.join(spec.variables)})"
        )
    rows = spec.rows_needed(horizon or spec.horizon)
    if len(rec) < rows:
        raise InputFileError(
            f"{rec.source}: {len(rec)} sample(s) are too few; the model's lags and horizon "
            f"need at least {rows} consecutive samples"
        )


def detect(
    model: MonitorModel,
    rec: Recording,
    alarm: AlarmConfig | None = None,
    horizon: int | None = None,
    exact: bool = False,
    gating: GatingConfig | None = None,
) -> Detection:
    """Run the detector over a whole recording (``exact``: see ``residual_series``;
    ``gating``: operating state, plausibility and validity, see ``monitor.detection.gating``)."""
    alarm = alarm or AlarmConfig()
    spec = model.spec
    check_recording(model, rec, horizon)
    gate = Gate(model, alarm.min_engine_rpm, gating)
    g = gate.series(rec)
    missing = ~np.isfinite(table(rec, spec.variables))
    inputs_ok = ~missing.any(axis=1)
    gated = gate.gated(g, inputs_ok)
    y_hat, e = residual_series(model, rec, gated, horizon, exact)
    e[gated] = np.nan
    stats = active(model)  # J first: the level rests on it
    series = {s.name: s.series(e, rec) for s in stats}
    j = series["J"]
    # The alarm machine compares the level with 1: each statistic against its threshold.
    level = level_series([(series[s.name], s.threshold_) for s in stats])
    decider = Decider(alarm, 1.0, make_isolator(model), model.window_n)
    run = _decide_all(decider, model, rec, gate, g, e, j, level, missing)
    states = run.states
    summary = {
        "alarm": run.first_alarm_t is not None,
        "first_alarm_t": run.first_alarm_t,
        "alarm_episodes": run.episodes,
        "fault": run.first_fault,
        "sensor_fault": bool(np.any(states == State.SENSOR_FAULT)),
        # Each statistic's largest value and threshold (null for one the model lacks), and
        # the largest alarm level, 1 being the alarm threshold.
        **statistic_keys(model, series),
        "max_level": float(np.nanmax(level)) if np.isfinite(level).any() else None,
        "threshold_rule": model.threshold.rule,
        "window_n": model.window_n,
        "horizon": horizon or spec.horizon,
        "samples": len(rec),
        "inactive_fraction": float(np.mean(states == State.INACTIVE)),
        "sensor_fault_fraction": float(np.mean(states == State.SENSOR_FAULT)),
        **gating_summary(rec, gate, g),
        "source": rec.source,
    }
    period = float(np.median(np.diff(rec.t))) if len(rec) > 1 else 0.01
    summary["out_of_range_values"] = out_of_range_values(
        gate.validity_values(rec), g.oor, gate.validity
    )
    summary["verdict"], summary["judged_s"], summary["not_judged_why"] = verdict(
        summary,
        states,
        j,
        g.op_state,
        g.oor,
        inputs_ok,
        rec["EngineSpeed"],
        model.window_n,
        period,
        describe(summary["out_of_range_values"]),
    )
    summary["rejected"] = rejected_counts(rec)
    summary["statistics"] = statistics_entries(model)
    summary["sensor_checks"] += stale_checks(rec, states, g.check, missing, spec.variables)
    return Detection(
        rec.t,
        y_hat,
        e,
        j,
        states,
        run.events,
        summary,
        gates=g,
        level=level,
        series=series,
        episodes=run.named,
    )


@dataclass
class _Run:
    states: np.ndarray
    events: list[dict[str, Any]]
    first_alarm_t: float | None
    first_fault: str | None  # the label held longest over the first alarm episode
    episodes: int
    # Every alarm episode: start_t and end_t (s from the first sample; end_t None while
    # open at the end of the log), fault (named once, from the votes of the whole episode,
    # as ``first_fault``) and votes (fault samples per isolation label).
    named: list[dict[str, Any]] = field(default_factory=list)


def _decide_all(
    decider: Decider,
    model: MonitorModel,
    rec: Recording,
    gate: Gate,
    g: GateSeries,
    e: np.ndarray,
    j: np.ndarray,
    level: np.ndarray,
    missing: np.ndarray,
) -> _Run:
    """The shared per-sample decision over every sample of the recording, in order."""
    n = len(rec)
    engine = rec["EngineSpeed"]
    inputs_ok = ~np.asarray(missing.any(axis=1))  # an array (numpy's stubs: or a scalar)
    stale = np.where(inputs_ok, -1, np.argmax(missing, axis=1))  # first missing model signal
    regimes = regimes_of(rec["SpoolCmd"] if rec.has("SpoolCmd") else np.zeros(n))
    states = np.empty(n, dtype=np.int8)
    # Quiet samples (normal operation, inputs complete and plausible, level <= 1) change
    # nothing in NORMAL but the isolation ring: runs of them go to skip_quiet at once, the
    # rest are decided one by one.  J finite means the sample was not gated (nor out of range).
    with np.errstate(invalid="ignore"):
        quiet = (
            (g.op_state == OpState.NORMAL)
            & inputs_ok
            & (g.check == 0)
            & (g.oor < 0)
            & (level <= 1.0)
        )
    stops = np.append(np.flatnonzero(~quiet), n)
    start = rec.meta.get("start_time_s")
    start_s = float(start) if isinstance(start, (int, float)) else None
    t_rel = rec.t - rec.t[0]
    run = _Run(states, [], None, None, 0)
    # Isolation votes over the first alarm episode: the label held longest names the fault
    # (it firms up as evidence accumulates, and may waver on the way).
    votes: dict[str, int] = {}
    in_first = False
    ep_votes: dict[str, int] = {}
    i = 0
    while i < n:
        if quiet[i] and decider.quiet():
            r = int(stops[np.searchsorted(stops, i)])
            decider.skip_quiet(e[i:r], regimes[i:r])
            states[i:r] = State.NORMAL
            i = r
            continue
        oor, check, sensor = int(g.oor[i]), int(g.check[i]), int(g.sensor[i])
        d = decider.decide(
            level[i],
            bool(inputs_ok[i]),
            engine[i],
            e[i],
            int(regimes[i]),
            int(g.op_state[i]),
            oor,
            check,
            sensor,
        )
        states[i] = d.state
        run.episodes += d.raised
        if d.raised and run.first_alarm_t is None:
            run.first_alarm_t = float(t_rel[i])
            in_first = True
        if d.raised:
            ep_votes = {}
            run.named.append({"start_t": float(t_rel[i]), "end_t": None, "votes": ep_votes})
        if d.state is State.FAULT and run.named:
            ep_votes[decider.fault] = ep_votes.get(decider.fault, 0) + 1
        if run.named and run.named[-1]["end_t"] is None and not d.episode_open:
            run.named[-1]["end_t"] = float(t_rel[i])
        if in_first:  # the first episode, short gaps included
            if d.state is State.FAULT:
                votes[decider.fault] = votes.get(decider.fault, 0) + 1
            in_first = d.episode_open
        if d.changed:
            run.events.append(
                event_record(
                    float(t_rel[i]),
                    d.state,
                    float(j[i]),
                    model.eps0,
                    decider.fault,
                    start_s,
                    int(g.op_state[i]),
                    gate.validity.signals[oor] if oor >= 0 else None,
                    check,
                    sensor,
                    model.spec.variables[stale[i]] if stale[i] >= 0 else None,
                )
            )
        i += 1
    run.first_fault = vote_name(votes)
    for ep in run.named:
        ep["fault"] = vote_name(ep["votes"])
    return run


def vote_name(votes: dict[str, int]) -> str | None:
    """The fault an episode's isolation votes name: the label held for the most samples,
    a known fault before ``unknown`` (None: no votes)."""
    known = {k: v for k, v in votes.items() if k != "unknown"}
    pool = known or votes
    return max(pool, key=pool.__getitem__) if pool else None


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
