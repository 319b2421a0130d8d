"""`monitor watch`: the screen, from frames a real daemon put on the bus, and the command in a
real terminal (tmux)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from live_support import REPO, live_config, own_udp_port, replay_settled, run_daemon

from monitor.codec.frames import FrameCodec
from monitor.codec.j1939.dtc import DEFAULT_FAULT_FMI, DEFAULT_FAULT_SPN
from monitor.resources import resource_path
from monitor.watch.render import j_bar, render
from monitor.watch.state import WatchState

LOG = resource_path("replay", "spool_wear.log")


def test_j_bar_puts_the_threshold_at_three_quarters() -> None:
    assert j_bar(1.0, 20) == "[###############|    ]  1.00"
    assert j_bar(0.0, 8) == "[      | ]  0.00"
    assert j_bar(10.0, 8).startswith("[######|#]")  # full, the threshold mark kept
    assert j_bar(None, 4) == "[    ]  n/a"


def test_the_screen_of_a_daemon_that_raised_spool_wear(tmp_path: Path) -> None:
    cfg = live_config(tmp_path)
    daemon, _, frames, _ = run_daemon(cfg, replay_settled(LOG))
    state = WatchState(FrameCodec.from_dbc(cfg.dbc))
    for m in frames:
        state.feed(m, now_mono=0.0)
    text = "\n".join(render(state, "virtual:test", now_mono=0.0, width=160))
    alarm = state.alarms["MON_Alarm"]
    assert alarm.state == "fault" and alarm.fault == "spool_wear"
    assert alarm.ratio is not None and alarm.ratio > 1.0
    assert "FAULT" in text and "spool_wear" in text
    spn, fmi = DEFAULT_FAULT_SPN["spool_wear"], DEFAULT_FAULT_FMI["spool_wear"]
    assert f"SPN {spn} FMI {fmi} OC 1 (fault spool_wear)" in text
    assert "amber" in text
    # The sensor values are the last frames' (the log's last HYD_Pressures frame, decoded).
    codec = FrameCodec.from_dbc(cfg.dbc)
    last = [m for m in frames if m.arbitration_id == codec.message("HYD_Pressures").frame_id][-1]
    pp = codec.decode_message(last).values["PP"]
    assert f"PP {pp:7.2f} bar" in text
    assert state.frames["HYD_Pressures"] == daemon.codec.counts.per_message["HYD_Pressures"]


@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed")
def test_watch_in_a_terminal_shows_the_bus_and_quits_on_q(tmp_path: Path) -> None:
    """`monitor watch` in tmux on a udp_multicast bus; a replay of the monitor's own frames
    (from a daemon run) shows on the screen; q ends it."""
    pytest.importorskip("msgpack")
    import can

    cfg = live_config(tmp_path)
    _, _, frames, _ = run_daemon(cfg, replay_settled(LOG))
    ours = [m for m in frames if (m.arbitration_id & 0xFF) == 0xA0]  # our source address
    session, group, port = f"watch{os.getpid()}", "239.74.163.7", own_udp_port()
    env = f"PYTHONPATH={REPO} CAN_CONFIG='{{\"port\": {port}}}'"
    cmd = f"{env} {sys.executable} -m monitor watch --interface udp_multicast --channel {group}"
    subprocess.run(
        ["tmux", "new-session", "-d", "-s", session, "-x", "160", "-y", "30", cmd], check=True
    )
    try:
        bus = can.Bus(interface="udp_multicast", channel=group, port=port)
        screen = ""
        for _ in range(300):  # until the screen shows the fault (the TUI needs a moment)
            for m in ours[-200:]:
                bus.send(m)
            screen = subprocess.run(
                ["tmux", "capture-pane", "-p", "-t", session], capture_output=True, text=True
            ).stdout
            if "spool_wear" in screen and "SPN" in screen:
                break
            time.sleep(0.1)
        bus.shutdown()
        assert "FAULT" in screen and "spool_wear" in screen and "SPN" in screen, screen
        subprocess.run(["tmux", "send-keys", "-t", session, "q"], check=True)
        for _ in range(100):
            alive = (
                subprocess.run(
                    ["tmux", "has-session", "-t", session], capture_output=True
                ).returncode
                == 0
            )
            if not alive:
                break
            time.sleep(0.1)
        assert not alive, "monitor watch did not quit on q"
    finally:
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
