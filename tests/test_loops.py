"""Several loops in one daemon (config/excavator4.yaml, dbc/excavator4.dbc): one bus reader,
each loop its own signals, model, MON_Alarm frame and J1939 address.

The four-loop log puts the shipped demo logs on the four loops (boom normal, stick piston
wear, bucket spool wear, swing spool stroke; faults from 45 s, replay/regenerate.sh), with
the boom's EngineSpeed and OilTemp shared.  What each loop must say is known from the log
that went into it; the daemon's events per loop must equal ``monitor detect --loop``'s.
Those logs are the single boom loop's on its own pump, so the config here is the shipped
one with the boom's model on every loop and the single loop's pump system."""

from __future__ import annotations

import collections
import dataclasses
import json
import tempfile
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest
import yaml
from live_support import assert_same_events, live_config, replay_settled, run_daemon

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.codec.logwrite import write_candump
from monitor.config.layout import row_layout
from monitor.config.settings import load_config
from monitor.detection.alarm import State
from monitor.detection.offline import detect
from monitor.errors import ConfigError
from monitor.live.daemon import Daemon
from monitor.live.loops import worst_state
from monitor.model.modelfile import load_model
from monitor.offline.recordings import loop_recording, wide_recording
from monitor.resources import resource_path
from monitor.sampling.bulk import recording_from_candump_bulk
from monitor.sampling.sampler import ROW_COLUMNS


def _boom_model_config(folder: Path) -> Path:
    """config/excavator4.yaml with the boom's model on every loop, on the boom loop's own
    compensated pump (the plausibility defaults): what the demo logs come from."""
    doc = yaml.safe_load(resource_path("config", "excavator4.yaml").read_text())
    boom = str(resource_path("config", "boom_default.model.npz"))
    doc["dbc"] = str(resource_path("dbc", "excavator4.dbc"))
    doc["model"] = boom
    for loop in doc["loops"]:
        loop["model"] = boom
    doc.pop("plausibility", None)
    doc.pop("pump", None)  # the pump rule is a load-sensing pump's
    path = folder / "excavator4_boom_models.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


CONFIG = _boom_model_config(Path(tempfile.mkdtemp(prefix="test-loops-")))
ONSET_S = 45.0
TRUTH = {"boom": "normal", "stick": "piston_wear", "bucket": "spool_wear", "swing": "spool_stroke"}
ALARM_SA = {"boom": 0xA0, "stick": 0xA1, "bucket": 0xA2, "swing": 0xA3}
FAULT_SPN = {"piston_wear": 520192, "spool_stroke": 520193, "spool_wear": 520194}


@pytest.fixture(scope="module")
def four_log(tmp_path_factory) -> Path:
    cfg = load_config(CONFIG)
    recs = {
        loop: recording_from_candump_bulk(resource_path("replay", f"{log}.log"))
        for loop, log in TRUTH.items()
    }
    path = tmp_path_factory.mktemp("loops") / "four.log"
    start = recs["boom"].meta["start_time_s"]
    write_candump(path, wide_recording(cfg, recs), FrameCodec.from_dbc(cfg.dbc), start)
    return path


@pytest.fixture(scope="module")
def run(tmp_path_factory, four_log) -> dict[str, Any]:
    cfg = live_config(tmp_path_factory.mktemp("loops-live"), CONFIG)
    # Each loop replays a shipped log of the reference machine, judged with its model: the
    # run declares that machine (excavator4.yaml itself declares none, see below).
    cfg = dataclasses.replace(cfg, machine=dataclasses.replace(cfg.machine, machine_id="reference"))
    daemon, events, frames, counts = run_daemon(cfg, replay_settled(four_log))
    return {"cfg": cfg, "daemon": daemon, "events": events, "frames": frames, "t0": counts.first_ts}


def test_each_loop_reads_its_own_signals_and_shares_engine_and_oil() -> None:
    cfg = load_config(CONFIG)
    columns, views = row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
    stick = dict(zip(views[1], columns, strict=True))
    assert stick["PP"] == "Stick_PP" and stick["SpoolCmd"] == "Stick_SpoolCmd"
    assert stick["EngineSpeed"] == "EngineSpeed" and stick["OilTemp"] == "OilTemp"
    assert "RodPos" not in views[3]  # the swing motor: RodPos: null
    assert len(columns) == 9 + 3 * 7 - 1  # boom's 9, three loops' own 7 less the swing rod


def test_without_loops_the_row_is_the_contract_row() -> None:
    cfg = load_config()
    columns, views = row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
    assert columns == ROW_COLUMNS and views == [ROW_COLUMNS]


def test_worst_state_orders_fault_sensor_normal_inactive() -> None:
    assert worst_state([State.INACTIVE, State.NORMAL]) is State.NORMAL
    assert worst_state([State.NORMAL, State.SENSOR_FAULT, State.INACTIVE]) is State.SENSOR_FAULT
    assert worst_state([State.SENSOR_FAULT, State.FAULT]) is State.FAULT


def test_loop_recording_gives_back_each_loops_signals(four_log) -> None:
    cfg = load_config(CONFIG)
    stick = loop_recording(four_log, cfg, "stick")
    original = recording_from_candump_bulk(resource_path("replay", "piston_wear.log"))
    boom = recording_from_candump_bulk(resource_path("replay", "normal.log"))
    for name in ("PP", "PA", "PB", "QP", "SpoolCmd", "RodPos"):
        np.testing.assert_allclose(stick[name], original[name], atol=0.01)  # DBC scaling 0.01
    np.testing.assert_allclose(stick["OilTemp"], boom["OilTemp"], atol=0.04)  # shared
    assert not loop_recording(four_log, cfg, "swing").has("RodPos")


def test_each_loop_alarms_for_its_own_fault_and_only_it(run) -> None:
    by_loop: dict[str, list[dict[str, Any]]] = {name: [] for name in TRUTH}
    for e in run["events"]:
        if "kind" not in e:  # the machine's finding lines name no loop of their own
            by_loop[e["loop"]].append(e)
    for loop, truth in TRUTH.items():
        faults = [e for e in by_loop[loop] if e["state"] == "fault"]
        if truth == "normal":
            assert not faults, f"{loop}: {faults}"
        else:
            # The name at the raise may be the look-alike (piston and spool wear residuals
            # are alike at first: the stick's first raise says spool_wear); the name the
            # loop settles on is checked on its alarm frames below.
            assert faults and faults[0]["fault"] in FAULT_SPN, f"{loop}: {by_loop[loop]}"
            # within 30 s: the swing motor's spool stroke (no rod position) is the slowest
            assert ONSET_S < faults[0]["t"] < ONSET_S + 30.0


def test_live_events_per_loop_equal_offline_detect(run, four_log) -> None:
    cfg = run["cfg"]
    for lc in cfg.loops:
        live = [e for e in run["events"] if e.get("loop") == lc.name]
        rec = loop_recording(four_log, cfg, lc.name)
        offline = detect(load_model(lc.model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
        assert_same_events(live, offline)


def _decoded(run: dict[str, Any], message: str) -> list[tuple[float, dict[str, float]]]:
    codec = FrameCodec.from_dbc(run["cfg"].dbc)
    fid = codec.message(message).frame_id
    out = []
    for m in run["frames"]:
        if m.arbitration_id == fid:
            d = codec.decode_message(m)
            assert d.ok, d.rejection
            out.append((m.timestamp - run["t0"], d.values))
    return out


def test_each_loop_has_its_own_alarm_frame(run) -> None:
    codes = {"piston_wear": 1, "spool_stroke": 2, "spool_wear": 3}  # MON_Alarm's value table
    messages = {
        "boom": "MON_Alarm",
        "stick": "MON_Alarm_Stick",
        "bucket": "MON_Alarm_Bucket",
        "swing": "MON_Alarm_Swing",
    }
    for loop, message in messages.items():
        frames = _decoded(run, message)
        assert frames[0][1]["State"] == 0
        fault = [(t, v) for t, v in frames if v["State"] == 1]
        if TRUTH[loop] == "normal":
            assert not fault
        else:
            assert fault and fault[0][0] > ONSET_S
            # The fault code the loop sends longest is its own fault.
            named = collections.Counter(v["Fault"] for _, v in fault)
            assert named.most_common(1)[0][0] == codes[TRUTH[loop]], f"{loop}: {named}"
        assert (0x0CFF4000 | ALARM_SA[loop]) == FrameCodec.from_dbc(run["cfg"].dbc).message(
            message
        ).frame_id


def _dm1_dtcs(run: dict[str, Any], sa: int) -> list[list[tuple[int, int]]]:
    """(SPN, FMI) per single-frame DM1 from source address ``sa`` (J1939-73 layout)."""
    out = []
    for m in run["frames"]:
        if m.arbitration_id == (0x18FECA00 | sa):
            d = bytes(m.data)
            dtcs = []
            for k in range(2, len(d) - 3, 4):
                spn = d[k] | d[k + 1] << 8 | (d[k + 2] >> 5) << 16
                if spn:
                    dtcs.append((spn, d[k + 2] & 0x1F))
            out.append(dtcs)
    return out


def test_each_loop_sends_dm1_from_its_own_address(run) -> None:
    for loop, truth in TRUTH.items():
        dm1 = _dm1_dtcs(run, ALARM_SA[loop])
        assert dm1, f"no DM1 from {ALARM_SA[loop]:#x}"
        sent = collections.Counter(dtc for dtcs in dm1 for dtc in dtcs)
        if truth == "normal":
            assert not sent, f"{loop}: {sent}"
            continue
        # The isolation may waver while evidence accumulates (piston and spool wear look
        # alike at first); the DTC the loop reports longest is its own fault.
        assert set(sent) <= {(spn, 7) for spn in FAULT_SPN.values()}, f"{loop}: {sent}"
        assert sent.most_common(1)[0][0] == (FAULT_SPN[truth], 7), f"{loop}: {sent}"


def test_status_shows_the_most_pressing_loop(run) -> None:
    status = _decoded(run, "MON_Status")
    assert status and any(v["State"] == 1 for _, v in status)  # the stick's fault
    assert run["daemon"].state is State.FAULT  # the swing's cleared, the others stay


def test_counts_sum_over_the_loops(run) -> None:
    counts = run["daemon"].counts()
    assert counts["ticks"] == 4 * run["daemon"].loops[0].ticker.ticks
    assert counts["alarm_frames"] == sum(lp.frames.sent for lp in run["daemon"].loops)


def test_detect_cli_reads_one_loop(four_log, tmp_path, capsys) -> None:
    summary = tmp_path / "s.json"
    rc = main(
        [
            "detect",
            str(four_log),
            "--config",
            str(CONFIG),
            "--loop",
            "bucket",
            "--summary",
            str(summary),
            "--j-every",
            "0",
        ]
    )
    # excavator4.yaml declares no machine_id: the shipped boom model on its loops is a
    # model of the reference machine, not of this excavator, so its alarm on the worn bucket
    # spool is withheld (not_judged, exit 3) and the summary says why.
    assert rc == 3
    s = json.loads(summary.read_text())
    assert s["loop"] == "bucket" and s["reference_model"] and not s["alarm"]
    assert s["verdict"] == "not_judged" and s["withheld"]["first_t"] > ONSET_S
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert lines and all(e["loop"] == "bucket" for e in lines)


def _config(tmp_path: Path, loops: str) -> Path:
    p = tmp_path / "m.yaml"
    p.write_text(
        f"dbc: {resource_path('dbc', 'excavator4.dbc')}\n"
        f"model: {resource_path('config', 'boom_default.model.npz')}\n"
        f"loops:\n{loops}"
    )
    return p


MODEL = resource_path("config", "boom_default.model.npz")


@pytest.mark.parametrize(
    "loops, says",
    [
        (
            f"  - {{name: boom, model: {MODEL}}}\n  - {{name: boom, model: {MODEL}}}\n",
            "loops[1].name 'boom' is also loops[0]'s",
        ),
        (
            f"  - {{name: stick, model: {MODEL}, signals: {{PX: Stick_PP}}}}\n",
            "loops[0].signals: unknown signal 'PX'",
        ),
        (
            f"  - {{name: stick, model: {MODEL}, signals: {{PP: Stick_PP, PA: Stick_PP}}}}\n",
            "DBC signal 'Stick_PP' would carry two",
        ),
        (f"  - {{name: Stick, model: {MODEL}}}\n", "loops[0].name must be lower case"),
        ("  - {name: stick, model: nowhere.npz}\n", "loops[0].model: no such file"),
        (
            f"  - {{name: stick, model: {MODEL}, source_address: 254}}\n",
            "loops[0].source_address must be a whole number 0..253",
        ),
    ],
)
def test_bad_loops_section_is_one_config_error(tmp_path, loops, says) -> None:
    path = _config(tmp_path, loops)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert says in str(info.value) and str(info.value).startswith(f"{path}: ")


@pytest.mark.parametrize(
    "loop, says",
    [
        ("signals: {PP: Stik_PP}", "loops[0].signals.PP: no signal 'Stik_PP' in"),
        ("alarm_message: MON_Alarm_Stik", "loops[0].alarm_message: no message 'MON_Alarm_Stik'"),
        ("alarm_message: HYD_Flow_Stick", "HYD_Flow_Stick in"),
    ],
)
def test_loop_naming_what_the_dbc_lacks_is_a_config_error(tmp_path, loop, says) -> None:
    cfg = load_config(_config(tmp_path, f"  - {{name: stick, model: {MODEL}, {loop}}}\n"))
    with pytest.raises(ConfigError) as info:
        row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
    assert says in str(info.value) and "excavator4.dbc" in str(info.value)


def test_cli_bad_loop_is_one_line_and_exit_2(four_log, tmp_path, capsys) -> None:
    rc = main(["detect", str(four_log), "--config", str(CONFIG), "--loop", "arm"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no loop 'arm'; loops: boom, stick, bucket, swing" in err[0]


def test_daemon_without_loops_events_have_no_loop_key(tmp_path) -> None:
    daemon = Daemon(live_config(tmp_path))
    try:
        assert [lp.name for lp in daemon.loops] == ["boom"] and daemon.loops[0].tag == {}
    finally:
        daemon.stop()


def _two_loops(tmp_path: Path, stick_model: Path, stick_pp: str = "Stick_PP") -> Path:
    p = tmp_path / "two.yaml"
    p.write_text(
        f"dbc: {resource_path('dbc', 'excavator4.dbc')}\nmodel: {MODEL}\n"
        f"bus: {{interface: virtual, channel: reload-{id(p)}}}\n"
        f"event_log: {{path: {tmp_path / 'ev.jsonl'}}}\n"
        f"black_box: {{directory: {tmp_path / 'bb'}}}\n"
        f"loops:\n  - {{name: boom, model: {MODEL}}}\n"
        f"  - {{name: stick, model: {stick_model}, alarm_message: MON_Alarm_Stick,\n"
        f"     signals: {{SpoolCmd: Stick_SpoolCmd, PumpDispCmd: Stick_PumpDispCmd,\n"
        f"               PP: {stick_pp}, PA: Stick_PA, PB: Stick_PB, QP: Stick_QP}}}}\n"
    )
    return p


def test_reload_swaps_each_loops_model_and_keeps_the_loop_layout(tmp_path, caplog) -> None:
    other = tmp_path / "stick.model.npz"
    other.write_bytes(MODEL.read_bytes())
    path = _two_loops(tmp_path, MODEL)
    daemon = Daemon(load_config(path))
    try:
        _two_loops(tmp_path, other)  # a new stick model only
        daemon.reload_now()
        assert [lp.cfg.model for lp in daemon.loops] == [MODEL, other]
        assert daemon.reloads == 1
        _two_loops(tmp_path, MODEL, stick_pp="Bucket_PP")  # a signal moved: needs a restart
        with caplog.at_level("WARNING", logger="monitor"):
            daemon.reload_now()
        assert "take effect at the next restart" in caplog.text
        assert daemon.loops[1].cfg.signals["PP"] == "Stick_PP"
        assert daemon.loops[1].cfg.model == other  # the whole loops section kept
        _two_loops(tmp_path, tmp_path / "gone.npz")  # a bad file keeps what runs
        daemon.reload_now()
        assert daemon.reloads == 2 and daemon.loops[1].cfg.model == other
    finally:
        daemon.stop()


def _request(pgn: int, to: int) -> can.Message:
    """A J1939 request (PGN 59904 = 0xEA00) from a service tool at 0xF9 (J1939-21)."""
    return can.Message(
        arbitration_id=0x18EA0000 | to << 8 | 0xF9,
        is_extended_id=True,
        data=pgn.to_bytes(3, "little"),
    )


def test_a_request_to_all_reaches_every_loop_one_to_an_address_only_its_loop(tmp_path) -> None:
    daemon = Daemon(live_config(tmp_path, CONFIG))
    try:
        daemon.frame(_request(65227, 0xFF))  # DM2 from everybody
        daemon.frame(_request(65227, 0xA2))  # DM2 from the bucket loop only
        assert [lp.diag.requests for lp in daemon.loops] == [1, 1, 2, 1]
    finally:
        daemon.stop()


def test_a_log_without_the_loops_frames_is_exit_3_naming_the_loop(capsys) -> None:
    rc = main(
        [
            "detect",
            str(resource_path("replay", "normal.log")),
            "--config",
            str(CONFIG),
            "--loop",
            "stick",
        ]
    )
    assert rc == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no frame carries loop stick's own signals (Stick_SpoolCmd" in err[0]
