"""`monitor detect` says what it judged: the verdict, the judged time, rejected frames, and
"not judged" (exit 3) when the data cannot support a verdict."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from detect_support import detect_cli
from naive_frames import recording_from_candump

from monitor.codec.logwrite import write_candump
from monitor.io.recording import Recording
from monitor.resources import resource_path
from monitor.sampling.read import read_recording

WINDOW_S = 30.0  # the shipped model's J window: N = 3000 samples at 100 Hz


def edited_log(tmp_path: Path, name: str, keep_s: float | None = None, **nan_cols: bool) -> Path:
    rec = read_recording(resource_path("replay", "normal.log"))
    keep = np.ones(len(rec), dtype=bool) if keep_s is None else rec.t - rec.t[0] < keep_s
    cols = {k: v[keep].copy() for k, v in rec.columns.items()}
    for col in nan_cols:
        cols[col][:] = np.nan  # the frames carrying it are never sent
    out = tmp_path / name
    write_candump(out, Recording(rec.t[keep] - rec.t[0], cols, name))
    return out


def test_healthy_log_is_judged_for_all_but_the_first_window(tmp_path: Path) -> None:
    rc, s, err, _ = detect_cli(resource_path("replay", "normal.log"), tmp_path)
    assert rc == 0, err
    assert s["verdict"] == "healthy" and s["rejected"] == {}
    # 90 s of samples; J needs a full window first: 90 - 30 = 60 s judged (one sample less
    # than 6,000 because the first full window ends at sample 3,000).
    assert s["judged_s"] == pytest.approx(90.0 - WINDOW_S, abs=0.02)
    assert "no hydraulic fault" in err


def test_a_log_without_commands_is_not_judged_exit_3(tmp_path: Path) -> None:
    log = edited_log(tmp_path, "nocmd.log", SpoolCmd=True, PumpDispCmd=True, EngineSpeed=True)
    rc, s, err, _ = detect_cli(log, tmp_path)
    assert rc == 3, err
    assert s["verdict"] == "not_judged" and s["judged_s"] == 0.0
    assert "not judged: no commands" in err and "HYD_Commands" in err
    assert not s["alarm"]


def test_a_recording_shorter_than_the_window_is_not_judged(tmp_path: Path) -> None:
    log = edited_log(tmp_path, "short.log", keep_s=20.0)
    rc, s, err, _ = detect_cli(log, tmp_path)
    assert rc == 3, err
    assert s["verdict"] == "not_judged"
    assert "shorter than the J window" in s["not_judged_why"]
    assert "not judged" in err


def test_rejected_frames_are_counted_per_message_and_reason(tmp_path: Path) -> None:
    lines = resource_path("replay", "normal.log").read_text().splitlines()
    # Corrupt the CRC (last byte) of the 100th HYD_Pressures frame (0CFF1021).
    hits = [i for i, line in enumerate(lines) if " 0CFF1021#" in line]
    k = hits[100]
    head, data = lines[k].rsplit("#", 1)
    lines[k] = f"{head}#{data[:-2]}{(int(data[-2:], 16) ^ 0xFF):02X}"
    log = tmp_path / "badcrc.log"
    log.write_text("\n".join(lines) + "\n")
    rc, s, err, _ = detect_cli(log, tmp_path)
    assert rc == 0, err
    # The corrupt frame is rejected; the next one's alive counter then skips one value.
    expected = {"HYD_Pressures": {"crc": 1, "counter_jump": 1}}
    assert s["rejected"] == expected
    assert "HYD_Pressures frames rejected: 1 crc, 1 counter_jump" in err
    # The frame-by-frame decoder of the daemon counts the same.
    counts = recording_from_candump(log).meta["counts"]
    assert counts["rejected_by_message"] == expected


def test_j_lines_in_fault_name_the_fault(tmp_path: Path) -> None:
    rc, s, _, lines = detect_cli(resource_path("replay", "spool_wear.log"), tmp_path)
    assert rc == 0 and s["verdict"] == "fault"
    j_fault = [x for x in lines if x["event"] == "j" and x["state"] == "fault"]
    assert j_fault and all(x["fault"] == "spool_wear" for x in j_fault)
    j_normal = [x for x in lines if x["event"] == "j" and x["state"] == "normal"]
    assert j_normal and all(x["fault"] is None for x in j_normal)


def test_an_engine_off_gap_inside_a_fault_is_one_episode(tmp_path: Path, model) -> None:
    """The shipped spool-wear log with the engine off for 3 s in the middle of the fault:
    the fault comes back after the gap as the same episode, with the same isolation."""
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect

    cfg = load_config()
    rec = read_recording(resource_path("replay", "spool_wear.log"))
    t = rec.t - rec.t[0]
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["EngineSpeed"][(t >= 70.0) & (t < 73.0)] = 0.0
    det = detect(
        model,
        Recording(rec.t, cols, "gap", dict(rec.meta)),
        cfg.alarm,
        cfg.horizon,
        gating=cfg.gating,
    )
    states = [(e["state"], e["fault"]) for e in det.events]
    assert det.summary["alarm_episodes"] == 1
    i = states.index(("inactive", None))
    assert states[i - 1] == states[i + 1] == ("fault", "spool_wear")


def test_a_sensor_fault_from_missing_frames_names_the_signal(tmp_path: Path) -> None:
    """QP's frames (HYD_Flow) stop for 2 s: the sensor fault names QP, check `stale`, in the
    events and in the summary's sensor checks; the verdict is sensor_fault."""
    rec = read_recording(resource_path("replay", "normal.log"))
    t = rec.t - rec.t[0]
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["QP"][(t >= 50.0) & (t < 52.0)] = np.nan  # the HYD_Flow frames are not sent
    log = tmp_path / "noflow.log"
    write_candump(log, Recording(rec.t - rec.t[0], cols, "noflow"))
    rc, s, err, lines = detect_cli(log, tmp_path)
    assert rc == 0, err
    faults = [x for x in lines if x["event"] == "state" and x["state"] == "sensor_fault"]
    assert faults and all((x["sensor"], x["sensor_check"]) == ("QP", "stale") for x in faults)
    assert s["verdict"] == "sensor_fault"
    stale = [c for c in s["sensor_checks"] if c["check"] == "stale"]
    assert [c["sensor"] for c in stale] == ["QP"]
    assert 50.0 <= stale[0]["first_t"] < 50.1


def test_not_judged_names_the_signal_outside_the_trained_range(tmp_path: Path, model) -> None:
    """Oil at 110 degC throughout, far above anything the shipped model was trained on: the
    "not judged" line names OilTemp, the temperature the log showed and the trained range."""
    rec = read_recording(resource_path("replay", "normal.log"))
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["OilTemp"][:] = 110.0
    log = tmp_path / "hot.log"
    write_candump(log, Recording(rec.t - rec.t[0], cols, "hot"))
    lo, hi = model.envelope.range_of("OilTemp")
    assert hi + 5.0 < 110.0  # beyond the range and its margin (5 degC at least)
    rc, s, err, _ = detect_cli(log, tmp_path)
    assert rc == 3, err
    assert s["verdict"] == "not_judged"
    trained = f"trained {lo:.4g}-{hi:.4g} degC"
    expected = f"outside the trained range 100% of the time (OilTemp 110 degC, {trained})"
    assert expected in s["not_judged_why"]
    assert f"not judged: {expected}" in err
    assert s["out_of_range_values"] == {
        "OilTemp": {
            "samples": s["out_of_range_samples"],
            "min": 110.0,
            "max": 110.0,
            "trained_min": round(lo, 3),
            "trained_max": round(hi, 3),
            "unit": "degC",
        }
    }
