"""A silent source is a sensor fault: HYD_Commands (EngineSpeed) missing while the pressures
and flow show a working machine is ``sensor_fault`` naming EngineSpeed (``stale``), not an
engine off; the same offline, per tick and in the daemon, with its DM1 DTC.  A machine that
really stopped (every message silent, or the pump at rest) stays ``inactive``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from detect_support import detect_cli as run_detect
from j1939_support import TP_CM_ID, TP_DT_ID, decode_dm, reassemble
from live_support import (
    assert_same_events,
    live_config,
    replay_settled,
    run_daemon,
    tick_recording,
)
from naive_frames import recording_from_candump

from monitor.codec.j1939.dtc import PGN_DM1
from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.detection.opstate import SilenceTracker, silent_source
from monitor.detection.ticker import Ticker
from monitor.io.recording import Recording
from monitor.resources import resource_path

CFG = load_config()
COMMANDS = "0CFF1203#"  # HYD_Commands (dbc: BO_ 2365526531 = 0x8CFF1203, extended)
LOG = resource_path("replay", "spool_wear.log")  # abrupt spool wear at 45 s
SETTLE_S = 1.0  # operating.silent_settle_s as shipped
STALE_S = 0.03  # 3 cycles of the 10 ms HYD_Commands (sampler stale_cycles)
ENGINE_SPN = 520192 + 16 + 2  # proprietary sensor SPNs in the order of dtc.py's list
SPOOL_SPN, PUMP_SPN = 520192 + 16, 520192 + 16 + 1


def cut_log(
    tmp_path: Path,
    name: str,
    start_s: float,
    end_s: float = 1e9,
    ids: tuple[str, ...] = (COMMANDS,),
) -> Path:
    """spool_wear.log without the frames of ``ids`` (all frames for ``("",)``) from
    ``start_s`` to ``end_s`` (log time from the first frame)."""
    lines = LOG.read_text().splitlines()
    t0 = float(lines[0].split()[0].strip("()"))

    def dropped(line: str) -> bool:
        t = float(line.split()[0].strip("()")) - t0
        return start_s <= t < end_s and any(i in line for i in ids)

    out = tmp_path / name
    out.write_text("".join(line + "\n" for line in lines if not dropped(line)))
    return out


def detect_cli(log: Path, tmp_path: Path) -> tuple[int, dict[str, Any], list[dict[str, Any]]]:
    rc, summary, _, lines = run_detect(log, tmp_path)
    changes = [e for e in lines if e["event"] == "state"]  # not the J once a second
    return rc, summary, changes


def _states(events: list[dict[str, Any]]) -> list[tuple[float, str, str | None, str | None]]:
    return [(e["t"], e["state"], e["sensor"], e["sensor_check"]) for e in events]


# -- the rule by hand ---------------------------------------------------------------------


def test_silence_starts_after_the_settle_time_with_flow_and_holds_while_pp_is_up() -> None:
    nan = np.nan
    # rest 5 bar, flow 2 L/min, settle 2 samples: a start needs a run of 3 samples of
    # EngineSpeed missing with PP above rest, and flow on that third sample or later.
    engine = np.array([2200, nan, nan, nan, nan, nan, nan, nan, nan, 2200, nan, nan, nan, nan])
    pp = np.array([100, 100, 100, 100, 100, 100, 3.0, 100, 100, 100, 100, nan, 100, 100])
    qp = np.array([10, 10, 10, 0.0, 5, 0, 0, 5, 5, 5, 5, 5, 5, 5])
    # 1-2: settling; 3: no flow; 4: flow, silent; 5: held without flow; 6: PP at rest ends
    # it; 7-8 a new run settling; 9 engine back; 10 settling; 11 PP stale ends it; 12-13
    # settling again.
    expected = [0, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0]
    got = silent_source(engine, pp, qp, 5.0, 2.0, 2)
    assert got.tolist() == [bool(x) for x in expected]
    tracker = SilenceTracker(5.0, 2.0, 2)
    steps = [
        tracker.step(float(e), float(p), float(q)) for e, p, q in zip(engine, pp, qp, strict=True)
    ]
    assert steps == got.tolist()


# -- monitor detect on the shipped fault log ------------------------------------------------


def test_detect_names_the_silent_commands_instead_of_engine_off(tmp_path: Path) -> None:
    rc, s, events = detect_cli(cut_log(tmp_path, "nocmd30.log", 30.0), tmp_path)
    assert rc == 0
    # Stale from 30 s + 3 cycles; silent once that has lasted the settle time and QP flows.
    t_stale = 30.0 + STALE_S
    sf = [e for e in events if e["state"] == "sensor_fault"]
    assert sf and t_stale + SETTLE_S - 1e-6 <= sf[0]["t"] < t_stale + SETTLE_S + 1.0
    assert (sf[0]["sensor"], sf[0]["sensor_check"], sf[0]["op_state"]) == (
        "EngineSpeed",
        "stale",
        "normal",
    )
    # Until the end of the log: one sensor fault, never inactive again, no alarm.
    assert not [e for e in events if e["t"] > sf[0]["t"] and e["state"] != "sensor_fault"]
    assert s["verdict"] == "sensor_fault" and not s["alarm"]
    assert s["sensor_checks"] == [
        {
            "sensor": "EngineSpeed",
            "check": "stale",
            "first_t": sf[0]["t"],
            "samples": round((90.0 - sf[0]["t"]) / 0.01) + 1,
        }
    ]


def test_rejected_commands_frames_are_a_silent_source_too(tmp_path: Path) -> None:
    """A node jamming the ID: HYD_Commands frames still arrive from 30 s but fail their CRC,
    so EngineSpeed goes stale exactly as if they had stopped."""
    lines = LOG.read_text().splitlines()
    t0 = float(lines[0].split()[0].strip("()"))
    out = []
    for line in lines:
        if COMMANDS in line and float(line.split()[0].strip("()")) - t0 >= 30.0:
            head, data = line.split("#")
            line = f"{head}#{data[:-2]}{int(data[-2:], 16) ^ 0xFF:02X}"  # CRC byte flipped
        out.append(line)
    log = tmp_path / "jammed.log"
    log.write_text("".join(x + "\n" for x in out))
    rc, s, events = detect_cli(log, tmp_path)
    assert rc == 0
    assert s["rejected"] == {"HYD_Commands": {"crc": 6001}}  # 30.00..90.00 s at 100 Hz
    sf = [e for e in events if e["state"] == "sensor_fault"]
    assert [(e["sensor"], e["sensor_check"]) for e in sf] == [("EngineSpeed", "stale")]
    assert 30.0 + STALE_S + SETTLE_S - 1e-6 <= sf[0]["t"] < 30.0 + STALE_S + SETTLE_S + 1.0
    assert s["verdict"] == "sensor_fault"


def test_the_full_log_still_raises_the_spool_wear_fault(tmp_path: Path) -> None:
    rc, s, events = detect_cli(LOG, tmp_path)
    assert rc == 0
    assert [e["state"] for e in events] == ["normal", "fault"]
    assert s["fault"] == "spool_wear" and not s["sensor_fault"] and s["sensor_checks"] == []


def test_commands_back_resume_the_normal_path_and_the_fault_is_raised(
    model, tmp_path: Path
) -> None:
    """HYD_Commands missing from 20 to 35 s: engine unknown for the settle time, then the
    sensor fault, normal after the recovery debounce, the wear fault after 45 s; the ticker
    gives the same events, sensor names included."""
    rec = recording_from_candump(cut_log(tmp_path, "gap.log", 20.0, 35.0))
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    t_stale = 20.0 + STALE_S
    states = _states(det.events)
    assert states[1] == (pytest.approx(t_stale), "inactive", None, None)
    assert states[2][1:] == ("sensor_fault", "EngineSpeed", "stale")
    assert t_stale + SETTLE_S - 1e-6 <= states[2][0] < t_stale + SETTLE_S + 1.0
    # Frames again from 35.00 s, their alive counter out of sequence after 15 s: the third
    # frame in sequence (35.02 s) is the first believed (the codec's resync), then sensor
    # fault for the recovery debounce (the 10th valid sample is normal again).
    back_s = 35.0 + 2 * 0.01
    recover_s = (CFG.alarm.sensor_recover_samples - 1) * 0.01
    assert states[3] == (pytest.approx(back_s), "sensor_fault", None, None)
    assert states[4] == (pytest.approx(back_s + recover_s), "normal", None, None)
    assert states[5][1] == "fault" and states[5][0] > 45.0 and det.summary["fault"] == "spool_wear"
    _, live = tick_recording(Ticker(model, CFG.alarm, CFG.horizon, gating=CFG.gating), rec)
    assert_same_events(live, det)
    assert _states(live) == states


# -- a machine that stopped stays inactive -------------------------------------------------


def test_every_message_silent_is_inactive_not_a_sensor_fault(tmp_path: Path) -> None:
    rc, s, events = detect_cli(cut_log(tmp_path, "quiet.log", 30.0, 40.0, ("",)), tmp_path)
    gap = [e for e in events if 30.0 <= e["t"] < 40.0]
    assert [e["state"] for e in gap] == ["inactive"]
    assert not any(
        c["check"] == "stale" and c["sensor"] == "EngineSpeed" for c in s["sensor_checks"]
    )


def _edited(rec: Recording, start: int, **cols: float) -> Recording:
    out = {k: v.copy() for k, v in rec.columns.items()}
    out["EngineSpeed"][start:] = np.nan
    for k, v in cols.items():
        out[k][start:] = v
    return Recording(rec.t, out, "edited", dict(rec.meta))


@pytest.mark.parametrize(
    ("case", "cols"),
    [
        ("pump at rest", {"PP": 0.4, "QP": 0.0}),  # bled to tank, no flow
        ("held, no flow", {"QP": 0.0}),  # pressure but nothing proves the pump turns
        ("pressures stale soon after", {}),  # key-off: PP silent 0.5 s after the commands
    ],
)
def test_a_stopped_machine_stays_inactive(model, case: str, cols: dict[str, float]) -> None:
    start = 3000  # 30 s
    rec = _edited(recording_from_candump(LOG), start, **cols)
    if not cols:
        for c in ("PP", "PA", "PB", "QP"):
            rec.columns[c][start + 50 :] = np.nan
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    after = [e for e in det.events if e["t"] >= rec.t[start] - rec.t[0] - 1e-9]
    assert [e["state"] for e in after] == ["inactive"], case
    assert after[0]["op_state"] == "engine_off"
    _, live = tick_recording(Ticker(model, CFG.alarm, CFG.horizon, gating=CFG.gating), rec)
    assert _states(live) == _states(det.events)


# -- the daemon and its DM1 ----------------------------------------------------------------


def test_daemon_gives_the_sensor_fault_and_a_dm1_naming_engine_speed(model, tmp_path: Path) -> None:
    log = cut_log(tmp_path, "nocmd.log", 30.0, 40.0)
    cfg = live_config(tmp_path)
    assert cfg.j1939.enabled
    daemon, events, frames, counts = run_daemon(cfg, replay_settled(log))
    det = detect(model, recording_from_candump(log), cfg.alarm, cfg.horizon, gating=cfg.gating)
    assert_same_events(events, det)
    assert _states(events) == _states(det.events)
    t_on = next(e["t"] for e in events if e["sensor"] == "EngineSpeed")
    # The DM1 during the sensor fault: the three HYD_Commands signals the model uses, each
    # with its SPN and FMI 9 (abnormal update rate), first occurrence.
    j1939 = [m for m in frames if m.arbitration_id in (TP_CM_ID, TP_DT_ID)]
    dm1 = [
        (g["t"] - counts.first_ts, decode_dm(g["data"])[1])
        for g in reassemble(j1939)
        if g["pgn"] == PGN_DM1
    ]
    silent = [(ENGINE_SPN, 9, 1), (PUMP_SPN, 9, 1), (SPOOL_SPN, 9, 1)]
    assert dm1 and all(sorted(d, reverse=True) == silent for _, d in dm1)
    assert dm1[0][0] == pytest.approx(t_on + 0.1, abs=0.011)  # BAM: 2 data packets later
