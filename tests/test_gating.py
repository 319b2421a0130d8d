"""Operating-state gating and model validity: detection only where the model was trained,
the same offline and per tick, and no change of decisions on data inside the envelope."""

from __future__ import annotations

import json
import logging

import can
import numpy as np
import pytest
from live_support import live_config, rows_of, settle, tick_recording, write_config
from naive_frames import recording_from_candump

from monitor.bus.replay import replay_log
from monitor.codec.frames import FrameCodec
from monitor.codec.logwrite import write_candump
from monitor.config.settings import OutputConfig, load_config
from monitor.detection.gating import GatingConfig
from monitor.detection.offline import detect, gated_residuals
from monitor.detection.opstate import OperatingConfig, OpState, OpStateTracker, op_states
from monitor.detection.ticker import Ticker
from monitor.errors import ConfigError
from monitor.io.recording import Recording
from monitor.live.daemon import Daemon
from monitor.live.outputs import AlarmFrames
from monitor.model.envelope import ValidityConfig, envelope_from_patterns
from monitor.model.modelfile import load_model, save_model
from monitor.model.residual import window_j
from monitor.resources import resource_path
from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate
from monitor.training.settings import (
    DGRNNSettings,
    IsolationSettings,
    StatisticSettings,
    TrainConfig,
)
from monitor.training.train import train

CFG = load_config()
MACHINE = load_machine()
LOGS = ("normal.log", "piston_wear.log", "spool_stroke.log", "spool_wear.log")


def edited(rec: Recording, **cols: np.ndarray) -> Recording:
    out = {k: v.copy() for k, v in rec.columns.items()}
    out.update(cols)
    return Recording(rec.t, out, "edited", dict(rec.meta))


def test_operating_state_by_hand() -> None:
    cfg = OperatingConfig(warmup_oil_c=30.0, warmup_hysteresis_c=2.0)
    engine = np.array([2200, 2200, 2200, 2200, 2200, 2200, 2200, 0, np.nan, 2200, 400, 2200.0])
    oil = np.array([np.nan, 20, 29, 30, 29, 28, 27.9, 27.9, 40, np.nan, 40, 29])
    N, W, E = OpState.NORMAL, OpState.WARM_UP, OpState.ENGINE_OFF
    # Warm until a reading says cold; warm again from 30 degC, cold again below 28 degC; a
    # missing reading keeps the last decision; engine off (or unknown) overrides.
    expected = [N, W, W, N, N, N, W, E, E, N, E, N]
    assert list(op_states(engine, oil, 500.0, cfg)) == expected
    tracker = OpStateTracker(500.0, cfg)
    assert [tracker.step(float(e), float(o)) for e, o in zip(engine, oil, strict=True)] == expected


# The evidence rules off (monitor.detection.evidence): an edit that makes the oil jump by
# 37 degC in one sample is what they doubt, rightly; here the warm-up itself is under test.
AT_ONCE = GatingConfig(
    operating=OperatingConfig(oil_rate_max_c_per_s=0.0, engine_confirm_s=0.0, oil_confirm_s=0.0)
)


def test_warm_up_is_inactive_and_reported(model) -> None:
    rec = recording_from_candump(resource_path("replay", "normal.log"))
    oil = rec["OilTemp"].copy()
    cold = (rec.t - rec.t[0] >= 10.0) & (rec.t - rec.t[0] < 25.0)
    oil[cold] = 20.0  # a cold stretch (as after a cold start) inside the recording
    rec2 = edited(rec, OilTemp=oil)
    # With the defaults the jump is believed after oil_confirm_s (1.5 s: the 150th reading
    # away from 57 degC, 1.49 s on) and warm-up reported 1.49 s after that.
    det = detect(model, rec2, CFG.alarm, CFG.horizon, gating=CFG.gating)
    warm_up = [e for e in det.events if e["op_state"] == "warm_up"]
    assert [(e["t"], e["state"]) for e in warm_up] == [(12.98, "inactive")]
    det = detect(model, rec2, CFG.alarm, CFG.horizon, gating=AT_ONCE)
    warm_up = [e for e in det.events if e["op_state"] == "warm_up"]
    assert [(e["t"], e["state"]) for e in warm_up] == [(10.0, "inactive")]
    assert det.summary["op_state_s"]["warm_up"] == pytest.approx(cold.sum() * 0.01)
    assert np.all(det.state[cold] == 3)  # MON_Alarm.State inactive
    assert np.all(np.isnan(det.j[cold]))  # window held
    assert det.summary["alarm"] is False
    _, events = tick_recording(Ticker(model, CFG.alarm, CFG.horizon, gating=AT_ONCE), rec2)
    strip = lambda evs: [{k: v for k, v in e.items() if k != "J"} for e in evs]  # noqa: E731
    assert strip(events) == strip(det.events)


def test_operation_outside_the_envelope_is_out_of_range_not_a_fault(model) -> None:
    """A pump displacement the model never saw (60 % instead of 100 %) gives a false
    hydraulic alarm when judged; gated, it is counted and logged as out_of_range."""
    cmd = make_cycle("boom", 120.0, 777)
    cmd.columns["PumpDispCmd"][6000:] = 60.0
    rec = simulate(cmd, MACHINE, seed=777)
    counted_only = GatingConfig(validity=ValidityConfig(gate=False))
    judged = detect(model, rec, CFG.alarm, 1, gating=counted_only)
    assert judged.summary["alarm"] is True
    det = detect(model, rec, CFG.alarm, 1, gating=GatingConfig())
    s = det.summary
    assert s["alarm"] is False
    assert s["out_of_range_samples"] == len(rec) - 6000
    assert s["out_of_range_signals"] == {"PumpDispCmd": len(rec) - 6000}
    assert [(e["t"], e["state"], e["out_of_range_signal"]) for e in det.events] == [
        (0.0, "normal", None),
        (60.0, "normal", "PumpDispCmd"),
    ]
    assert np.all(np.isnan(det.j[6000:]))
    _, events = tick_recording(Ticker(model, CFG.alarm, 1, gating=GatingConfig()), rec)
    assert [(e["t"], e["state"], e["out_of_range"]) for e in events] == [
        (e["t"], e["state"], e["out_of_range"]) for e in det.events
    ]
    # The daemon sends MON_Alarm (and counts alarms) on state changes only, not on this one.
    ticker = Ticker(model, CFG.alarm, 1, gating=GatingConfig())
    changes = [(tk.t_s, tk.state_changed) for tk in map(ticker.tick, rows_of(rec)) if tk.changed]
    assert changes == [(0.0, True), (60.0, False)]


@pytest.mark.parametrize("log", LOGS)
def test_gating_leaves_decisions_on_in_envelope_data_unchanged(model, log: str) -> None:
    """On the shipped logs (inside the training envelope, healthy sensors) J is exactly the
    engine-gated J of before, so every state and event decision is the same."""
    rec = recording_from_candump(resource_path("replay", log))
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    _, e_old, _, _ = gated_residuals(model, rec, CFG.alarm.min_engine_rpm, CFG.horizon)
    assert np.array_equal(det.j, window_j(e_old, model.window_n), equal_nan=True)
    s = det.summary
    assert s["out_of_range_samples"] == 0 and s["sensor_checks"] == []
    assert s["op_state_s"]["normal"] == pytest.approx(len(rec) * 0.01)
    assert all(e["op_state"] == "normal" and e["sensor"] is None for e in det.events)


def run_at(seed: int, oil_c: float, duration_s: float = 60.0) -> Recording:
    cmd = make_cycle("boom", duration_s, seed)
    cmd.columns["OilTemp"][:] = oil_c
    return simulate(cmd, MACHINE, seed=seed)


def test_trained_model_keeps_its_envelope_and_old_files_derive_one(tmp_path, caplog) -> None:
    recs = [run_at(s, oil) for s, oil in ((21, 40.0), (22, 60.0))]
    m = train(
        recs,
        TrainConfig(
            DGRNNSettings(max_patterns=300),
            statistics=StatisticSettings(window_n=300),
            isolation=IsolationSettings("none"),
        ),
    )
    env = m.envelope
    assert env is not None and env.source == "training"
    for name in ("SpoolCmd", "OilTemp", "PA", "QP"):
        values = np.concatenate([r[name] for r in recs])
        assert env.range_of(name) == (values.min(), values.max())
        occ = env.occupancy[env.signals.index(name)]
        assert sum(occ) == pytest.approx(1.0)
    # Trained at 40 and 60 degC only: 50 degC is inside the range (judged, not out of
    # range) but in a bin no training row fell into; 40 degC is covered.
    mid = detect(m, run_at(21, 50.0), gating=GatingConfig()).summary
    assert mid["out_of_range_samples"] == 0 and mid["sparse_coverage"] == {"OilTemp": 1.0}
    edge = detect(m, run_at(21, 40.0), gating=GatingConfig()).summary
    assert "OilTemp" not in edge["sparse_coverage"]
    path = tmp_path / "m.npz"
    save_model(path, m)
    assert load_model(path).envelope == env
    # A version-2 file from before the envelope: loads, derives it from the patterns, says so.
    m.envelope = None
    old = tmp_path / "old.npz"
    save_model(old, m)
    with caplog.at_level(logging.INFO, logger="monitor"):
        back = load_model(old)
    assert "no stored training envelope" in caplog.text
    assert back.envelope == envelope_from_patterns(back) and back.envelope.source == "patterns"
    for name in ("SpoolCmd", "OilTemp"):
        lo, hi = back.envelope.range_of(name)
        tlo, thi = env.range_of(name)
        assert tlo - 1e-9 <= lo <= hi <= thi + 1e-9  # centroids lie inside the rows' range
    det = detect(back, recs[0], gating=GatingConfig())
    assert det.summary["envelope"] == "patterns"


@pytest.mark.parametrize(
    "yaml, key",
    [
        ("operating:\n  warmup_oil_c: warm\n", "operating.warmup_oil_c"),
        ("operating:\n  warmup_oil_c: 400\n", "operating.warmup_oil_c"),
        ("plausibility:\n  stuck_s: -1\n", "plausibility.stuck_s"),
        ("plausibility:\n  pressure_min_bar: 500\n", "pressure_max_bar"),
        ("plausibility:\n  stuck_seconds: 3\n", "plausibility.stuck_seconds"),
        ("validity:\n  gate: 3\n", "validity.gate"),
        ("validity:\n  margin_c: -2\n", "validity.margin_c"),
    ],
)
def test_bad_gating_config_names_file_and_key(tmp_path, yaml: str, key: str) -> None:
    path = write_config(tmp_path, yaml)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(path) in str(info.value) and key in str(info.value)


def test_mon_status_carries_operating_state_and_flags() -> None:
    codec = FrameCodec.from_dbc(CFG.dbc)
    frames = AlarmFrames(codec, OutputConfig())
    msg = frames.status(3, 10, 0, 0, 0.0, int(OpState.WARM_UP), True, True)
    dbc = codec.message("MON_Status").dbc_message
    values = dbc.decode(msg.data, decode_choices=True)
    assert str(values["State"]) == "inactive"
    assert str(values["OpState"]) == "warm_up"
    assert str(values["OutOfRange"]) == "out_of_range"
    assert str(values["SensorCheck"]) == "active"
    plain = dbc.decode(frames.status(0, 1, 0, 0, 0.0).data, decode_choices=False)
    assert (plain["OpState"], plain["OutOfRange"], plain["SensorCheck"]) == (0, 0, 0)


def test_daemon_logs_and_announces_the_operating_state(tmp_path, model) -> None:
    """On the bus: a cold stretch then a pump displacement the model never saw; the event
    log equals ``monitor detect`` of the same log, and MON_Status says warm-up at the end."""
    base = recording_from_candump(resource_path("replay", "normal.log"))
    keep = base.t - base.t[0] < 40.0
    cols = {k: v[keep].copy() for k, v in base.columns.items()}
    t = base.t[keep] - base.t[0]
    cols["PumpDispCmd"][(t >= 10.0) & (t < 20.0)] = 60.0
    cols["OilTemp"][t >= 30.0] = 15.0
    log = tmp_path / "cold.log"
    write_candump(log, Recording(t, cols, "cold"))
    offline = detect(model, recording_from_candump(log), CFG.alarm, CFG.horizon, gating=CFG.gating)
    cfg = live_config(tmp_path)
    listener = can.Bus(interface="virtual", channel=cfg.bus.channel)
    sender = can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True)
    status_id = FrameCodec.from_dbc(CFG.dbc).message("MON_Status").frame_id
    daemon = Daemon(cfg)
    daemon.start()
    frames = []
    try:
        counts = replay_log(log, sender, speed=None)
        settle(daemon, counts.sent)
        while (m := listener.recv(0)) is not None:
            frames.append(m)
        # One more heartbeat, sent after the last row was ticked, shows the last state.
        while (m := listener.recv(10.0)) is not None:
            frames.append(m)
            if m.arbitration_id == status_id:
                break
    finally:
        daemon.stop()
        sender.shutdown()
    listener.shutdown()
    lines = cfg.event_log.path.read_text().splitlines()
    live = [json.loads(x) for x in lines]

    # J to rounding; mono and seq are the daemon's own (monotonic clock, log sequence).
    def strip(evs):
        return [{k: v for k, v in e.items() if k not in ("J", "mono", "seq")} for e in evs]

    assert strip(live) == strip(offline.events)
    assert {e["out_of_range_signal"] for e in live} == {None, "PumpDispCmd"}
    assert live[-1]["op_state"] == "warm_up" and live[-1]["state"] == "inactive"
    codec = FrameCodec.from_dbc(CFG.dbc)
    status = [
        codec.decode_message(m).values
        for m in frames
        if m.arbitration_id == codec.message("MON_Status").frame_id
    ]
    assert status[-1]["OpState"] == OpState.WARM_UP and status[-1]["State"] == 3
