"""Offline detection: a recording through the DGRNN, J(k+1), the threshold and the alarm machine.

The per-sample decisions are those of ``AlarmMachine``, the same object the live daemon
steps once per 100 Hz tick, so a recording gives the same events at a desk as on the bus.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.detection.alarm import AlarmConfig, Isolator, State, regimes_of
from monitor.detection.decision import Decider, Decision, event_record
from monitor.detection.episodes import Alarms, EpisodeLog
from monitor.detection.gating import Gate, GateSeries, GatingConfig
from monitor.detection.opstate import OpState
from monitor.detection.summary import detection_summary
from monitor.errors import InputFileError
from monitor.io.recording import Recording
from monitor.model.dgrnn import predict_series
from monitor.model.modelfile import MonitorModel
from monitor.model.spec import table
from monitor.model.statistic import active, level_series, naming_series
from monitor.signals import source_signal


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
    # Each alarm episode, named once from the isolation votes over all of it (see
    # ``monitor.detection.episodes``).
    episodes: list[dict[str, Any]] = field(default_factory=list)


def make_isolator(model: MonitorModel) -> Isolator | None:
    iso = model.isolation
    if not iso.labels:
        return None
    return Isolator(iso.labels, iso.centroids, len(model.spec.outputs), iso.min_similarity)


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
    missing = [source_signal(n) for n in dict.fromkeys(needed) if not rec.has(n)]
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
    reference: str | None = None,
) -> Detection:
    """Run the detector over a whole recording (``exact``: see ``residual_series``;
    ``gating``: operating state, plausibility and validity, see ``monitor.detection.gating``;
    ``reference``: why ``model`` is another machine's, ``machinecard.reference_reason``: its
    hydraulic alarms are withheld and the summary's ``withheld`` says when and why)."""
    alarm = alarm or AlarmConfig()
    check_recording(model, rec, horizon)
    gate = Gate(model, alarm.min_engine_rpm, gating)
    g = gate.series(rec)
    missing = ~np.isfinite(table(rec, model.spec.variables))
    gated = gate.gated(g, ~missing.any(axis=1))
    y_hat, e = residual_series(model, rec, gated, horizon, exact)
    e[gated] = np.nan
    stats = active(model)  # J first: the level rests on it
    beyond_c = gate.beyond(g, ~missing.any(axis=1))  # gated for the oil alone: its oil
    series = {s.name: s.series_beyond(e, rec, beyond_c) for s in stats}
    # The alarm machine compares the level with 1: each statistic against its threshold.
    pairs = [(series[s.name], s.threshold_) for s in stats]
    beyond, wide = np.isfinite(beyond_c), [s.beyond_oil for s in stats]
    level = level_series(pairs, beyond, wide)
    named = naming_series(pairs, [s.names for s in stats], beyond, wide)
    decider = Decider(alarm, 1.0, make_isolator(model), model.window_n, reference)
    run = _decide_all(decider, model, rec, gate, g, e, series["J"], level, missing, named)
    summary = detection_summary(
        model, rec, gate, g, run, series, level, horizon, missing, reference
    )
    return Detection(
        rec.t,
        y_hat,
        e,
        series["J"],
        run.states,
        run.events,
        summary,
        gates=g,
        level=level,
        series=series,
        episodes=run.named,
    )


def _quiet(g: GateSeries, inputs_ok: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Samples that change nothing in NORMAL but the isolation ring: normal operation,
    inputs complete and plausible, level <= 1 (J finite means the sample was not gated,
    nor out of range)."""
    with np.errstate(invalid="ignore"):
        return (
            (g.op_state == OpState.NORMAL)
            & inputs_ok
            & (g.check == 0)
            & (g.oor < 0)
            & (level <= 1.0)
        )


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
    named: np.ndarray,
) -> Alarms:
    """The shared per-sample decision over every sample of the recording, in order; runs
    of quiet samples go to ``skip_quiet`` at once, the rest are decided one by one."""
    n = len(rec)
    engine = rec["EngineSpeed"]
    inputs_ok = ~np.asarray(missing.any(axis=1))  # an array (numpy's stubs: or a scalar)
    stale = np.where(inputs_ok, -1, np.argmax(missing, axis=1))  # first missing model signal
    regimes = regimes_of(rec["SpoolCmd"] if rec.has("SpoolCmd") else np.zeros(n))
    states = np.empty(n, dtype=np.int8)
    quiet = _quiet(g, inputs_ok, level)
    stops = np.append(np.flatnonzero(~quiet), n)
    start = rec.meta.get("start_time_s")
    start_s = float(start) if isinstance(start, (int, float)) else None
    t_rel = rec.t - rec.t[0]
    episodes, events = EpisodeLog(), []
    i = 0
    while i < n:
        if quiet[i] and decider.quiet():
            r = int(stops[np.searchsorted(stops, i)])
            decider.skip_quiet(e[i:r], regimes[i:r])
            states[i:r] = State.NORMAL
            i = r
            continue
        status = int(g.op_state[i]), int(g.oor[i]), int(g.check[i]), int(g.sensor[i])
        d = decider.decide(
            level[i], bool(inputs_ok[i]), engine[i], e[i], int(regimes[i]), *status, named[i]
        )
        states[i] = d.state
        episodes.add(d, float(t_rel[i]), decider.fault)
        if d.changed:
            t_s, stale_i = float(t_rel[i]), int(stale[i])
            stale_name = source_signal(model.spec.variables[stale_i]) if stale_i >= 0 else None
            event = _event(
                t_s, d, float(j[i]), model.eps0, decider.fault, start_s, gate, g, i, stale_name
            )
            events.append(event)
        i += 1
    return episodes.result(states, events)


def _event(
    t_s: float,
    d: Decision,
    j: float,
    eps0: float,
    fault: str,
    start_s: float | None,
    gate: Gate,
    g: GateSeries,
    i: int,
    stale_signal: str | None,
) -> dict[str, Any]:
    """The event line of sample ``i`` (its status changed), as the daemon writes it."""
    oor = int(g.oor[i])
    return event_record(
        t_s,
        d.state,
        j,
        eps0,
        fault,
        start_s,
        int(g.op_state[i]),
        gate.oor_name(oor),
        int(g.check[i]),
        int(g.sensor[i]),
        stale_signal,
    )
