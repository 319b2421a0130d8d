"""A start mid-operation is warming, never a sensor fault (issue 43): each signal is stale only
once it has missed its own cycle time (the DBC's GenMsgCycleTime) by the margin, counted from
the first frame.  The 1 Hz OilTemp of a log cut mid-run comes up to a second after the first
frame; before this rule it read as a failed sensor until then, offline (verdict
``sensor_fault``) and live (MON_Alarm State 2 and a DM1 at a daemon restart)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from j1939_support import DM1_ID, decode_dm, reassemble
from live_support import assert_same_events, live_config, replay_settled, run_daemon
from naive_frames import recording_from_candump

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.codec.j1939.dtc import PGN_DM1
from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.live.outputs import ALARM
from monitor.model.modelfile import load_model
from monitor.resources import resource_path
from monitor.sampling.bulk import recording_from_candump_bulk

LOG = resource_path("replay", "normal.log")
OIL = "18FF1300#"  # HYD_OilTemp, sent once a second
CUT_S = 37.3  # 0.7 s after an OilTemp frame: the next one comes 0.7 s into the cut log


def _log_time(line: str) -> float:
    return float(line.split()[0].strip("()"))


def cut(tmp_path: Path, name: str, start_s: float = CUT_S, oil_until_s: float = 1e9) -> Path:
    """normal.log from ``start_s`` on (log time from its first frame), without OilTemp frames
    from ``oil_until_s`` on (in the cut log's time)."""
    lines = LOG.read_text().splitlines()
    t0 = _log_time(lines[0])
    kept = [x for x in lines if _log_time(x) - t0 >= start_s]
    t1 = _log_time(kept[0])
    kept = [x for x in kept if OIL not in x or _log_time(x) - t1 < oil_until_s]
    out = tmp_path / name
    out.write_text("".join(x + "\n" for x in kept))
    return out


def _summary(log: Path, tmp_path: Path) -> dict:
    out = tmp_path / f"{log.stem}.json"
    assert main(["detect", str(log), "--summary", str(out), "--j-every", "0"]) == 0
    return json.loads(out.read_text())


def _first_oil_s(log: Path) -> float:
    lines = log.read_text().splitlines()
    return next(_log_time(x) for x in lines if OIL in x) - _log_time(lines[0])


def test_log_cut_mid_operation_is_judged_healthy(tmp_path) -> None:
    log = cut(tmp_path, "mid.log")
    first_oil = _first_oil_s(log)
    assert first_oil == pytest.approx(0.69)
    summary = _summary(log, tmp_path)
    assert summary["verdict"] == "healthy"
    assert summary["sensor_checks"] == [] and summary["sensor_fault_fraction"] == 0
    # Row t = 0 is the instant OilTemp was first seen, with every signal fresh.
    rec = recording_from_candump_bulk(log)
    first = _log_time(log.read_text().splitlines()[0])
    assert rec.meta["start_time_s"] == pytest.approx(first + first_oil, abs=1e-6)
    assert rec.t[0] == 0 and all(np.isfinite(rec[n]).all() for n in rec.columns)
    ref = recording_from_candump(log)  # the frame-by-frame sampler: the same rows
    assert ref.meta == rec.meta
    np.testing.assert_array_equal(rec.t, ref.t)
    for name in ref.columns:
        np.testing.assert_array_equal(rec[name], ref[name])


def test_signal_that_stops_is_stale_after_its_own_period_and_margin(tmp_path) -> None:
    log = cut(tmp_path, "stops.log", oil_until_s=20.0)
    lines = log.read_text().splitlines()
    t1 = _log_time(lines[0])
    last_oil = max(_log_time(x) - t1 for x in lines if OIL in x) - _first_oil_s(log)
    summary = _summary(log, tmp_path)
    assert summary["verdict"] == "sensor_fault"
    (check,) = summary["sensor_checks"]
    assert (check["sensor"], check["check"]) == ("OilTemp", "stale")
    # Stale from the first 10 ms instant past 3 cycles (3 x 1000 ms) after its last frame.
    assert last_oil + 3.0 < check["first_t"] <= last_oil + 3.0 + 0.01 + 1e-6


def test_signal_never_seen_is_stale_from_its_own_deadline(tmp_path) -> None:
    log = cut(tmp_path, "never.log", oil_until_s=0.0)
    summary = _summary(log, tmp_path)
    assert summary["verdict"] == "sensor_fault"
    (check,) = summary["sensor_checks"]
    assert (check["sensor"], check["check"]) == ("OilTemp", "stale")
    # Warming until 3 x 1000 ms after the first frame: the first row is then stale.
    assert check["first_t"] == 0
    rec = recording_from_candump_bulk(log)
    first = _log_time(log.read_text().splitlines()[0])
    assert rec.meta["start_time_s"] == pytest.approx(first + 3.01, abs=1e-6)
    assert np.isnan(rec["OilTemp"]).all() and np.isfinite(rec["PP"]).all()


def test_daemon_restart_mid_operation_sends_no_sensor_fault(tmp_path) -> None:
    log = cut(tmp_path, "restart.log")
    cfg = live_config(tmp_path)
    assert cfg.j1939.enabled
    _, events, frames, _ = run_daemon(cfg, replay_settled(log))
    codec = FrameCodec.from_dbc()
    alarm_id = codec.message(ALARM).frame_id
    states = [
        codec.decode_message(m).values["State"] for m in frames if m.arbitration_id == alarm_id
    ]
    assert states and 2 not in states
    dm1 = [
        decode_dm(g["data"])[1]
        for g in reassemble(m for m in frames if m.arbitration_id == DM1_ID)
        if g["pgn"] == PGN_DM1
    ]
    assert dm1 and all(dtcs == [(0, 0, 0)] for dtcs in dm1)  # no DTC active, ever
    assert "sensor_fault" not in {e["state"] for e in events}
    offline = load_config()
    det = detect(
        load_model(offline.model),
        recording_from_candump_bulk(log),
        offline.alarm,
        offline.horizon,
        gating=offline.gating,
    )
    assert_same_events([e for e in events if e["t"] <= det.t[-1] + 1e-6], det)
