"""The one adapter between the fleet and our `monitor train` / `monitor detect` code paths.

Every import of training and detection code lives here, so a move of those modules changes
this file only.  A fleet row is computed from the very summary `monitor detect --summary`
writes (same reader, same config, same ``detect`` call), so the two agree bit for bit.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from monitor.fleet.episodes import log_episodes

# Columns of RESULTS/events.parquet besides machine and log; the whole event is in `event`.
EVENT_KEYS = ("t", "time", "state", "J", "threshold", "fault")


@dataclass
class Judged:
    """One log judged: the row's detector keys and its state-change events."""

    row: dict[str, Any]
    events: list[dict[str, Any]]


def _config(config_path: str | None):  # noqa: ANN202 - MonitorConfig, imported lazily
    from monitor.config.settings import load_config

    return load_config(None if config_path is None else Path(config_path))


def model_to_bytes(model: Any) -> bytes:
    """A MonitorModel as the bytes of its .model.npz file (what workers receive)."""
    from monitor.model.modelfile import save_model

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.npz"
        save_model(path, model)
        return path.read_bytes()


def model_from_bytes(data: bytes) -> Any:
    """The MonitorModel of .model.npz bytes, checked like `monitor detect --model` does."""
    from monitor.model.modelfile import load_model

    fd, name = tempfile.mkstemp(suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        return load_model(name)
    finally:
        os.unlink(name)


def default_model_bytes(
    model_path: str | None, config_path: str | None, loop: str | None = None
) -> bytes:
    """The model `monitor detect [--loop LOOP]` uses without --model (the config's, or its
    loop's), or ``model_path``."""
    from monitor.offline.loopjob import loop_config

    cfg = _config(config_path)
    if model_path is None and loop is not None:
        return Path(loop_config(cfg, loop).model).read_bytes()
    return Path(model_path or cfg.model).read_bytes()


def config_loops(config_path: str | None) -> list[str]:
    """The loops a config declares (``loops:``; one: the log judged as one loop)."""
    return [lc.name for lc in _config(config_path).monitored_loops]


class _Commissioning(TypedDict):
    """The :class:`~monitor.training.settings.TrainConfig` settings commissioning sets, by
    their `monitor train` names (recorded in each model's trained-from.json)."""

    folds: int
    lend: bool
    support_check: bool


#: How a machine is commissioned, as `monitor train --folds 4` with its other defaults: J's
#: threshold from residuals cross-fitted over the whole commissioning run (each minute
#: predicted by a model fitted on the others), not from its last quarter held out: J0 rests
#: on every minute, and the final model has seen the run's whole oil temperature range (the
#: last quarter of a warming run is its hottest oil).  Three simulated fleets: no false
#: alarm in 258 healthy logs against 1 (docs/benchmarks.md, "Commissioning cross-fitted, J
#: alone").  The statistics beside J are asked for as `monitor train` asks for them, and the
#: support rule (``monitor.training.support``) decides whether each one's held-out data
#: earns its threshold: one 20-minute run is one session, so B is off with the rule's
#: reason, and on when the commissioning folder holds the sessions it needs.  The default
#: model lends its patterns where the machine's own data has none
#: (``monitor.training.fill``).  Recorded in each model's trained-from.json.
COMMISSIONING: _Commissioning = {"folds": 4, "lend": True, "support_check": True}


def train_model_bytes(
    paths: list[str],
    config_path: str | None = None,
    isolation: str = "sim",
    reference: bytes | None = None,
    machine_id: str | None = None,
    loop: str | None = None,
) -> bytes:
    """`monitor train REC... --out M --folds 4 [--isolation I] [--reference R] [--loop L]`
    with its other defaults (:data:`COMMISSIONING`): the model file's bytes
    (``reference``: the reference model's bytes; ``machine_id``: the machine commissioned,
    recorded in the model as `monitor train` records the config's ``machine_id``).  With
    ``loop``, that loop of whole-machine recordings, with `monitor train --loop`'s preset,
    neighbours' inputs and card (``monitor.offline.loopjob``); a section model has no
    simulated fault signatures (isolation ``none``, as `monitor train --loop` defaults)."""
    from monitor.model.machinecard import card_for
    from monitor.offline.loopjob import loop_card, section_inputs
    from monitor.offline.recordings import read_loop
    from monitor.signals import ROD_SPEED
    from monitor.training.settings import (
        DGRNNSettings,
        IsolationSettings,
        StatisticSettings,
        ThresholdSettings,
        TrainConfig,
    )
    from monitor.training.train import train

    cfg = _config(config_path)
    recordings = [read_loop(p, cfg, loop) for p in paths]
    ref = None if reference is None else model_from_bytes(reference)
    if loop is None:
        dgrnn = DGRNNSettings(lend=COMMISSIONING["lend"])
    else:
        preset, neighbours = section_inputs(cfg, loop)
        # A loop is commissioned as its reference was trained: a rod speed it predicts too.
        rod_speed = ref is not None and ROD_SPEED.name in ref.spec.outputs
        dgrnn = DGRNNSettings(
            preset=preset, lend=COMMISSIONING["lend"], neighbours=neighbours, rod_speed=rod_speed
        )
        isolation = "none" if neighbours else isolation
    settings = TrainConfig(
        dgrnn=dgrnn,
        thresholds=ThresholdSettings(folds=COMMISSIONING["folds"]),
        statistics=StatisticSettings(support_check=COMMISSIONING["support_check"]),
        isolation=IsolationSettings(method=isolation),
    )
    card = None if loop is None else loop_card(cfg, loop, recordings, machine_id)
    model = train(recordings, settings, reference=ref)
    model.card = card or card_for(None, None, None, machine_id)
    return model_to_bytes(model)


def statistic_notes(model_bytes: bytes) -> dict[str, str]:
    """Every statistic of the family by name: ``on``, or ``off: ...`` with the reason
    `monitor train` recorded in the model (the support rule's line, or not asked for)."""
    from monitor.model.statistic import statistics_entries

    model = model_from_bytes(model_bytes)
    return {name: entry["why"] for name, entry in statistics_entries(model).items()}


def _drift(j: np.ndarray, j_median: float | None) -> float | None:
    """The log's median J over the model's median J on its own normal data, judged out
    of sample (``monitor train`` keeps it; None for models from before, or no J)."""
    if not j.size or not j_median or not j_median > 0:
        return None
    return float(np.median(j)) / float(j_median)


def threshold_note(model_path: Path) -> str | None:
    """One line when the machine's J0 rests on one event of its commissioning run
    (``monitor train``'s note, kept in the model file), else None; None for a model file
    that cannot be read (the report then says nothing rather than fail)."""
    from monitor.errors import MonitorError
    from monitor.model.modelfile import load_model

    try:
        event = load_model(model_path).training.get("threshold_one_event")
    except MonitorError:
        return None
    if not event:
        return None
    return (
        f"J0 rests on one event ({event['ratio']:.1f} x any other window's, "
        f"{Path(event['source']).name} at {event['t_s'] / 60:.1f} min)"
    )


def ratio_column(name: str) -> str:
    """The logs table's column of a statistic's largest value over its threshold:
    ``max_j_ratio`` (J / eps0), ``max_b_ratio`` (B / b0), ..."""
    return f"max_{name.lower()}_ratio"


def statistics() -> list[tuple[str, str, str]]:
    """Every statistic of the family (``monitor.model.statistic``) as (name, its threshold's
    name, its column in the logs table), J first."""
    from monitor.model.statistic import registry

    return [(s.name, s.threshold_key, ratio_column(s.name)) for s in registry()]


def statistic_ratios(summary: dict[str, Any]) -> dict[str, float | None]:
    """A summary's largest value over the threshold of every statistic of the family, by
    its column in the logs table (None: not in the model, or never judged)."""
    from monitor.model.statistic import registry

    return {ratio_column(stat.name): stat.peak_ratio(summary) for stat in registry()}


def _judged(
    model_bytes: bytes, path: str, config_path: str | None, machine_id: str | None, loop: str | None
) -> Any:  # monitor.offline.loopjob.Judged, imported lazily
    """`monitor detect PATH --model M [--loop LOOP]`'s judging, one implementation."""
    from monitor.offline.loopjob import check_model, judge_recording

    cfg = _config(config_path)
    model = model_from_bytes(model_bytes)
    check_model(model, cfg, loop, "the machine's model")
    return cfg, model, judge_recording(model, path, cfg, loop, machine_id)


def judge_log(
    model_bytes: bytes,
    path: str,
    config_path: str | None = None,
    machine_id: str | None = None,
    loop: str | None = None,
) -> Judged:
    """`monitor detect PATH --model M --j-every 0 [--loop LOOP]` with the config's
    ``machine_id`` the fleet's machine ``machine_id``: its summary as row keys (``loop``
    among them), its events.  A model not commissioned on that machine (the default model
    of a machine without commissioning) withholds its hydraulic alarms, the row says
    ``reference_model``."""
    cfg, model, judged = _judged(model_bytes, path, config_path, machine_id, loop)
    rec, det = judged.rec, judged.det
    s = json.loads(json.dumps(det.summary))  # exactly what --summary writes
    eps0 = float(s["threshold"])
    j = det.j[np.isfinite(det.j)]
    counts = rec.meta.get("counts")
    frames = int(counts.get("frames", 0)) if isinstance(counts, dict) else None
    row = {
        "verdict": s["verdict"],
        "alarm": bool(s["alarm"]),
        "fault": s["fault"],
        "sensor_fault": bool(s["sensor_fault"]),
        # Each statistic's largest value over its threshold: max_j_ratio, max_b_ratio, ...
        **statistic_ratios(s),
        "p95_j_ratio": float(np.percentile(j, 95)) / eps0 if j.size else None,
        "judged_s": float(s["judged_s"]),
        "first_alarm_t": s["first_alarm_t"],
        "frames": frames,
        "rejected": json.dumps(s["rejected"], sort_keys=True),
        "max_j": s["max_J"],
        "eps0": eps0,
        "samples": int(s["samples"]),
        "max_level": s.get("max_level"),
        "p50_j_ratio": float(np.median(j)) / eps0 if j.size else None,
        "p50_j_drift": _drift(j, model.training.get("j_median")),
        "reference_model": bool(s["reference_model"]),
        "loop": loop,
    }
    events = [json.loads(json.dumps(dict(e, event="state"))) for e in det.events]
    end_s = float(rec.t[-1] - rec.t[0]) if len(rec) else 0.0
    row["episodes"] = log_episodes(det.episodes, events, end_s, cfg.j1939)
    return Judged(row, events)


def detect_frames(
    model_bytes: bytes, path: str, config_path: str | None = None, loop: str | None = None
) -> int:
    """`monitor detect PATH --model M [--loop LOOP]` without its output: load the model,
    read the log, run the detector; the log's frames (what `monitor fleet bench` times
    beside the fleet)."""
    _cfg, _model, judged = _judged(model_bytes, path, config_path, None, loop)
    rec = judged.rec
    counts = rec.meta.get("counts")
    return int(counts.get("frames", 0)) if isinstance(counts, dict) else 0


#: Signals the fleet page plots around an alarm (those a log has).
TRACE_SIGNALS = ("PP", "PA", "PB", "QP", "SpoolCmd", "OilTemp", "EngineSpeed")


def trace_log(
    model_bytes: bytes,
    path: str,
    config_path: str | None = None,
    loop: str | None = None,
    machine_id: str | None = None,
) -> dict[str, Any]:
    """A log (its loop ``loop``) of machine ``machine_id`` judged again as `monitor detect`
    does, for the fleet page's plot around an alarm: t (s from the first sample), the
    signals of ``TRACE_SIGNALS`` it has, J / eps0 and the alarm level (1.0 = alarm)."""
    _cfg, model, judged = _judged(model_bytes, path, config_path, machine_id, loop)
    rec, det = judged.rec, judged.det
    return {
        "t": rec.t - rec.t[0],
        "signals": {s: np.asarray(rec[s], float) for s in TRACE_SIGNALS if rec.has(s)},
        "j_ratio": det.j / model.eps0,
        "level": det.level,
    }
