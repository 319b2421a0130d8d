"""The shared pump of a whole machine in `monitor fleet run`: its margin law commissioned on
the machine's own commissioning logs (``monitor.training.pump.commission_pump``, cross-fitted
as the loops' models are) and every log judged with the pump rule (``monitor.detection.pump``,
the rule `monitor detect --pump` and the daemon tick), a row with ``loop`` ``pump``.

Beside ``monitor.fleet.pipeline`` (the loops' adapter), the one place the fleet imports the
pump's training and detection code.  A pump whose commissioning data do not support a
threshold (the model file says why) is judged ``not_judged`` with that reason, never healthy.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

from monitor.fleet.pipeline import COMMISSIONING, Judged

PUMP = "pump"
PUMP_FAULT = "pump_wear"
#: Why the pump of a machine without commissioning data is not judged.
UNCOMMISSIONED = "no commissioning data: the pump's margin law is each machine's own"


def _config(config_path: str | None):  # noqa: ANN202 - MonitorConfig, imported lazily
    from monitor.config.settings import load_config

    return load_config(None if config_path is None else Path(config_path))


def train_pump_bytes(paths: list[str], config_path: str | None, machine_id: str) -> bytes:
    """The pump model file (JSON bytes) of machine ``machine_id`` from its commissioning
    recordings ``paths``, with the config's load-sensing margin."""
    from monitor.config.pump import pump_columns
    from monitor.model.pumplaw import PumpModel
    from monitor.offline.recordings import machine_rows
    from monitor.training.pump import commission_pump

    cfg = _config(config_path)
    recordings: list[Any] = []  # each recording's rows (numpy arrays)
    columns: tuple[str, ...] = ()
    for p in paths:
        columns, rows, _ = machine_rows(p, cfg)
        recordings.append(rows)
    cols = pump_columns(cfg, columns)
    margin = cfg.gating.plausibility.pump.ls_margin_bar
    model: PumpModel = commission_pump(recordings, cols, margin, COMMISSIONING["folds"])
    trained = {
        "recordings": [Path(p).name for p in paths],
        "machine_id": machine_id,
        "cross_fitted_folds": COMMISSIONING["folds"],
    }
    return (json.dumps(replace(model, trained=trained).to_dict(), indent=2) + "\n").encode()


def train_pump_task(paths: list[str], config: str | None, machine_id: str) -> bytes:
    return train_pump_bytes(paths, config, machine_id)


def pump_notes(model_bytes: bytes) -> dict[str, str]:
    """Whether the pump rule is on and why (``trained-from.json``'s ``statistics``, as the
    loops' statistics): ``on``, ``on (...)`` with the support rule's warning, or ``off: ...``."""
    from monitor.model.pumplaw import pump_model_from_text

    model = pump_model_from_text(model_bytes.decode("utf-8"), "the machine's pump model")
    if not model.on:
        return {PUMP: f"off: {model.off_reason}"}
    warning = model.support.get("warning")
    return {PUMP: f"on ({warning})" if warning else "on"}


def _episodes(events: list[dict[str, Any]], end_s: float, j1939: Any) -> str:
    """The pump's alarm episodes (a run of ``fault`` events) as the ``episodes`` column's
    JSON text (``monitor.fleet.episodes``), each with the DM1 code of ``pump_wear``."""
    out: list[dict[str, Any]] = []
    for e in events:
        if e["state"] == "fault" and (not out or not out[-1]["open"]):
            out.append({"kind": "fault", "start_t": e["t"], "end_t": end_s, "open": True})
        elif e["state"] != "fault" and out and out[-1]["open"]:
            out[-1].update(end_t=e["t"], open=False)
    for ep in out:
        ep.update(
            name=PUMP_FAULT,
            check=None,
            votes={},  # named by the pump rule, not by isolation's votes
            spn=int(j1939.fault_spn[PUMP_FAULT]),
            fmi=int(j1939.fault_fmi[PUMP_FAULT]),
            duration_s=round(ep["end_t"] - ep["start_t"], 3),
        )
    return json.dumps(out, sort_keys=True)


def judge_pump_log(model_bytes: bytes, path: str, config_path: str | None) -> Judged:
    """`monitor detect PATH --pump` with the machine's pump model: its summary as a row's
    keys (``loop`` ``pump``; ``max_level`` the largest window over the threshold,
    ``judged_s`` and ``samples`` the steady open flow it was judged on, ``alarm_since_t``
    when the window of its first alarm began), its events."""
    from monitor.config.pump import pump_columns
    from monitor.detection.pump import judge_rows
    from monitor.model.pumplaw import pump_model_from_text
    from monitor.offline.recordings import machine_rows

    cfg = _config(config_path)
    model = pump_model_from_text(model_bytes.decode("utf-8"), "the machine's pump model")
    columns, rows, start_s = machine_rows(path, cfg)
    det = judge_rows(model, pump_columns(cfg, columns), rows, start_s)
    s = json.loads(json.dumps(det.summary))
    events = [json.loads(json.dumps(dict(e, event="state"))) for e in det.events]
    first = next((e for e in events if e["state"] == "fault"), None)
    peak, threshold = s["max_margin_residual_bar"], s["threshold_bar"]
    row = {
        "verdict": s["verdict"],
        "alarm": bool(s["alarm"]),
        "fault": s["fault"],
        "sensor_fault": False,
        "judged_s": float(s["counted_s"]),
        "first_alarm_t": s["first_alarm_t"],
        "samples": round(float(s["counted_s"]) * 100),
        "max_level": peak / threshold if peak is not None and threshold else None,
        "reference_model": False,
        "loop": PUMP,
        "not_judged_why": s["not_judged_why"],
        "alarm_since_t": None if first is None else first["window_from_t"],
    }
    end_s = float(rows[-1, 0] - rows[0, 0]) if len(rows) else 0.0
    row["episodes"] = _episodes(events, end_s, cfg.j1939)
    return Judged(row, events)


def judge_pump_task(model_bytes: bytes, path: str, config: str | None) -> dict[str, Any]:
    """A worker's task: the pump's row keys and events of one log, or why it failed."""
    from monitor.errors import MonitorError

    try:
        judged = judge_pump_log(model_bytes, path, config)
        return {"row": judged.row, "events": judged.events, "error": None}
    except (MonitorError, OSError, ValueError, KeyError) as exc:
        return {"row": {}, "events": [], "error": f"{type(exc).__name__}: {exc}"}


def trace_pump_log(model_bytes: bytes, path: str, config_path: str | None) -> dict[str, Any]:
    """A log judged again by the pump rule for the pump's page, in the shape of
    ``monitor.fleet.pipeline.trace_log``: t (s from the first row), PP and the sections'
    total flow as ``QP``, and the rule's statistic over its threshold (``j_ratio``, held
    between windows; NaN before the first), named by ``stat_name``."""
    import numpy as np

    from monitor.config.pump import pump_columns
    from monitor.detection.pump import PumpRule
    from monitor.model.pumplaw import pump_model_from_text
    from monitor.offline.recordings import machine_rows

    cfg = _config(config_path)
    model = pump_model_from_text(model_bytes.decode("utf-8"), "the machine's pump model")
    columns, rows, _ = machine_rows(path, cfg)
    cols = pump_columns(cfg, columns)
    rule = PumpRule(model, cols)
    ratio = np.empty(len(rows))
    for i, row in enumerate(rows.tolist()):
        rule.tick(row)
        ratio[i] = rule.level
    return {
        "t": rows[:, 0] - rows[0, 0],
        "signals": {"PP": rows[:, cols.pp], "QP": rows[:, list(cols.qp)].sum(axis=1)},
        "j_ratio": ratio,
        "level": None,
        "stat_name": "margin residual / threshold",
    }
