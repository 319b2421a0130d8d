"""One frame is not evidence: a forged OilTemp or EngineSpeed frame (right CRC, right next
alive counter) injected into a log during a raised fault changes neither the operating state
nor the alarm; a real cold start or key-off still does, after the confirmation time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from live_support import assert_same_events, live_config, replay_settled, run_daemon, tick_recording
from naive_frames import recording_from_candump

from monitor.codec.frames import FrameCodec
from monitor.config.settings import load_config
from monitor.detection.evidence import (
    OilBelief,
    StateConfirmer,
    believed_oil,
    confirmed_states,
)
from monitor.detection.offline import detect
from monitor.detection.opstate import OperatingConfig, OpState
from monitor.detection.ticker import Ticker
from monitor.errors import ConfigError
from monitor.io.recording import Recording
from monitor.resources import resource_path

CFG = load_config()
LOG = resource_path("replay", "spool_wear.log")
N, W, E = OpState.NORMAL, OpState.WARM_UP, OpState.ENGINE_OFF


def test_oil_belief_by_hand() -> None:
    # 2 degC/s, at least one second's worth (2 degC); a jump is believed on its 3rd reading.
    oil = [50.0, 50.0, 51.9, 10.0, 10.0, 51.9, 10.0, 10.0, 10.0, 10.0, np.nan, 52.0]
    expected = [50.0, 50.0, 51.9, 51.9, 51.9, 51.9, 51.9, 51.9, 10.0, 10.0, 10.0, 10.0]
    # 10.0 at index 3, 4 doubted (2 readings), 51.9 resets the doubt; 6, 7 doubted, 8 is
    # the third in a row: believed.  52.0 at 11 is 42 degC from 10.0, 3 samples (0.03 s)
    # on: doubted, so 10.0 stands.
    assert believed_oil(np.array(oil), 2.0, 3).tolist() == expected
    b = OilBelief(2.0, 3)
    assert [b.step(v) for v in oil] == expected
    # Slow change is followed: 2 degC over 1 s of samples.
    ramp = 40.0 + np.arange(200) * 0.01
    np.testing.assert_array_equal(believed_oil(ramp, 2.0, 3), ramp)
    # A long gap allows more: after 30 s without a reading, 50 degC apart is believed.
    gap = np.concatenate([[20.0], np.full(3000, np.nan), [70.0]])
    assert believed_oil(gap, 2.0, 3)[-1] == 70.0
    # Off: rate 0 believes every reading (a missing one keeps the last).
    off = believed_oil(np.array(oil), 0.0, 3)
    assert off[10] == 10.0 and np.delete(off, 10).tolist() == np.delete(oil, 10).tolist()


def test_state_confirmation_by_hand() -> None:
    # An engine start or stop needs 3 samples, warm-up beginning or ending 4; a change
    # while EngineSpeed is missing counts at once.
    computed = np.array([N, E, N, E, E, E, W, W, W, W, N, N, N, N, W, E], dtype=np.int8)
    missing = np.zeros(len(computed), dtype=bool)
    missing[15] = True
    expected = [N, N, N, N, N, E, E, E, W, W, W, W, W, N, N, E]
    assert confirmed_states(computed, missing, 3, 4).tolist() == expected
    c = StateConfirmer(3, 4)
    assert [c.step(int(s), bool(m)) for s, m in zip(computed, missing, strict=True)] == expected


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_recording_functions_equal_the_per_sample_classes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 5000
    oil = np.repeat(40.0 + np.cumsum(rng.normal(0, 0.3, n // 100)), 100)
    spikes = rng.choice(n, 30, replace=False)
    oil[spikes] = rng.uniform(-40, 150, 30)
    oil[rng.choice(n, 300, replace=False)] = np.nan
    b = OilBelief(2.0, 150)
    np.testing.assert_array_equal(believed_oil(oil, 2.0, 150), [b.step(v) for v in oil])
    computed = np.repeat(rng.choice([N, W, E], 500), rng.integers(1, 20, 500))[:n]
    missing = rng.random(len(computed)) < 0.01
    c = StateConfirmer(5, 150)
    stepped = [c.step(int(s), bool(m)) for s, m in zip(computed, missing, strict=True)]
    assert confirmed_states(computed, missing, 5, 150).tolist() == stepped


def test_bad_evidence_config_is_one_clear_error() -> None:
    with pytest.raises(ConfigError, match="operating.oil_rate_max_c_per_s"):
        OperatingConfig(oil_rate_max_c_per_s=-1.0)
    with pytest.raises(ConfigError, match="operating.engine_confirm_s"):
        OperatingConfig(engine_confirm_s=100.0)


# -- forged frames in a log ---------------------------------------------------------------


def forged(tmp: Path, at_s: float, message: str, values: dict[str, float]) -> Path:
    """``LOG`` with one forged ``message`` frame right behind its first genuine frame from
    ``at_s`` on: valid CRC and the alive counter the next genuine frame will carry, so only
    its value gives it away.  It holds until that next genuine frame."""
    codec = FrameCodec.from_dbc()
    frame_id = f"{codec.message(message).frame_id:08X}"
    lines = LOG.read_text().splitlines()
    t0 = float(lines[0].split(")")[0][1:])
    k = next(
        i
        for i, x in enumerate(lines)
        if f" {frame_id}#" in x and float(x.split(")")[0][1:]) - t0 >= at_s
    )
    stamp, _, data = lines[k].partition(" can0 ")
    counter = int(data.split("#")[1][12:14], 16) & 0x0F  # byte 6, low nibble
    fake = codec.encode(message, values, counter=counter + 1)
    # Right behind the genuine frame, in the same sample: the one the sampler keeps.
    lines.insert(k + 1, f"{stamp} can0 {frame_id}#{fake.hex().upper()}")
    out = tmp / "forged.log"
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.fixture(scope="module")
def genuine(model):
    rec = recording_from_candump(LOG)
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    t_fault = next(e["t"] for e in det.events if e["state"] == "fault")
    return det, t_fault


def strip(events):
    return [{k: v for k, v in e.items() if k != "J"} for e in events]


@pytest.mark.parametrize(
    "message, values",
    [
        ("HYD_OilTemp", {"OilTemp": 0.0}),  # 0 degC: a cold machine, warm-up
        ("HYD_Commands", {"SpoolCmd": 0.0, "PumpDispCmd": 100.0, "EngineSpeed": 0.0}),
    ],
    ids=["OilTemp-0degC", "EngineSpeed-0rpm"],
)
def test_a_forged_frame_does_not_drop_a_raised_fault(
    tmp_path, model, genuine, message, values
) -> None:
    det0, t_fault = genuine
    log = forged(tmp_path, t_fault + 5.0, message, values)
    rec = recording_from_candump(log)
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    # The forged reading is in the data the detector saw...
    col = "OilTemp" if message == "HYD_OilTemp" else "EngineSpeed"
    assert np.nanmin(rec[col][rec.t - rec.t[0] > t_fault]) == 0.0
    # ...and changes no event: no warm-up, no engine off, no inactive inside the fault.
    assert strip(det.events) == strip(det0.events)
    assert det.summary["alarm_episodes"] == det0.summary["alarm_episodes"] == 1
    assert det.summary["op_state_s"] == det0.summary["op_state_s"]
    # The daemon's per-tick path agrees sample by sample.
    _, events = tick_recording(Ticker(model, CFG.alarm, CFG.horizon, gating=CFG.gating), rec)
    assert strip(events) == strip(det.events)


def test_the_daemon_keeps_the_fault_through_a_forged_oil_temp_frame(tmp_path, genuine) -> None:
    """On a virtual bus: the log with the forged 0 degC frame replayed to the daemon gives
    the state changes of the genuine log, one fault episode and no inactive inside it."""
    det0, t_fault = genuine
    log = forged(tmp_path, t_fault + 5.0, "HYD_OilTemp", {"OilTemp": 0.0})
    _, events, _, _ = run_daemon(live_config(tmp_path), replay_settled(log))
    assert_same_events(events, det0)
    assert [e["state"] for e in events if e["t"] > t_fault] == []  # the fault holds to the end


def test_a_real_cold_start_and_key_off_are_still_reported(model) -> None:
    """Oil cooling through the warm-up line at 1 degC/s (within the rate limit) and then the
    engine stopped: warm-up is reported oil_confirm_s after the oil crosses 28 degC (the
    line less the hysteresis), engine off engine_confirm_s after EngineSpeed reads 0."""
    rec = recording_from_candump(resource_path("replay", "normal.log"))
    t = rec.t - rec.t[0]
    cols = {k: v.copy() for k, v in rec.columns.items()}
    oil0 = cols["OilTemp"][0]
    cols["OilTemp"] = np.where(t < 10.0, oil0, np.maximum(oil0 - (t - 10.0), 20.0))
    cols["EngineSpeed"][t >= 70.0] = 0.0
    edited = Recording(rec.t, cols, "cooling", dict(rec.meta))
    det = detect(model, edited, CFG.alarm, CFG.horizon, gating=CFG.gating)
    first = {}
    for e in det.events:
        first.setdefault(e["op_state"], e["t"])
    t_cold = t[np.flatnonzero(cols["OilTemp"] < 28.0)[0]]
    assert first["warm_up"] == pytest.approx(t_cold + 1.49, abs=0.006)
    assert first["engine_off"] == pytest.approx(70.0 + 0.04, abs=0.006)
