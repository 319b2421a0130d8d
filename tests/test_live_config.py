"""config/monitor.yaml validation and the daemon's process behaviour (signals)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from live_support import REPO, write_config

from monitor.cli import main
from monitor.config.settings import load_config
from monitor.errors import ConfigError
from monitor.resources import resource_path

SHIPPED = resource_path("config", "monitor.yaml")


def test_shipped_config_has_every_live_section() -> None:
    cfg = load_config()
    assert cfg.bus.interface == "socketcan" and cfg.bus.channel == "can0"
    assert cfg.bus.bitrate == 500_000
    assert cfg.black_box.pre_s == 30.0 and cfg.black_box.post_s == 10.0
    assert cfg.outputs.status_period_s == 1.0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("bus:\n  chanel: can0\n", "unknown key bus.chanel"),
        ("bus:\n  bitrate: fast\n", "bus.bitrate must be a number"),
        ("bus:\n  bitrate: 5\n", "bus.bitrate must be between"),
        ("bus:\n  queue_frames: 10.5\n", "bus.queue_frames must be a whole number"),
        ("bus:\n  kernel_filters: 1\n", "bus.kernel_filters must be true or false"),
        ("bus:\n  options: {fd: [1]}\n", "bus.options must be a mapping"),
        ("bus: can0\n", "section 'bus' must be a mapping"),
        ("outputs:\n  alarm_repeat_s: 0\n", "outputs.alarm_repeat_s must be > 0"),
        ("black_box:\n  pre_s: -1\n", "black_box.pre_s must be >= 0"),
        ("black_box:\n  max_files: true\n", "black_box.max_files must be a number"),
        ("event_log:\n  path: ''\n", "event_log.path must be a path"),
        ("alarms: {}\n", "unknown key(s) alarms"),
        ("alarm:\n  clear_ratio: 2\n", "clear_ratio"),
    ],
)
def test_bad_config_is_one_clear_error(tmp_path, extra: str, message: str) -> None:
    with pytest.raises(ConfigError) as exc:
        load_config(write_config(tmp_path, extra))
    assert message in str(exc.value)
    assert str(tmp_path / "monitor.yaml") in str(exc.value)
    assert "\n" not in str(exc.value)


def test_missing_files_are_named(tmp_path) -> None:
    with pytest.raises(ConfigError, match="cannot read config"):
        load_config(tmp_path / "nope.yaml")
    p = write_config(tmp_path, "dbc: ../dbc/monitor.dbc\nmodel: missing.npz\n", base=False)
    with pytest.raises(ConfigError, match="dbc: no such file"):
        load_config(p)


def test_run_with_a_bad_config_exits_2(tmp_path, capsys) -> None:
    assert main(["run", "--config", str(write_config(tmp_path, "bus:\n  speed: 1\n"))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown key bus.speed" in err[0]


def _wait_for(proc: subprocess.Popen, text: str, lines: list[str], timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        line = proc.stderr.readline()  # type: ignore[union-attr]
        if not line:
            break
        lines.append(line)
        if text in line:
            return
    raise AssertionError(f"{text!r} not seen; stderr so far: {''.join(lines)}")


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
def test_run_reloads_on_sighup_and_stops_cleanly_on_sigterm(tmp_path) -> None:
    """The daemon as a process on a virtual bus of its own: SIGHUP reloads, SIGTERM ends it
    with exit 0 after the ordered stop.  (Frames through the daemon: test_live_e2e.)"""
    cfg = write_config(
        tmp_path,
        "bus:\n  interface: virtual\n  channel: sig\n"
        f"event_log:\n  path: {tmp_path / 'ev.jsonl'}\n"
        f"black_box:\n  directory: {tmp_path / 'bb'}\n",
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "monitor", "run", "--config", str(cfg)],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    lines: list[str] = []
    try:
        _wait_for(proc, "monitoring virtual:sig", lines, 60.0)
        proc.send_signal(signal.SIGHUP)
        _wait_for(proc, "reloaded", lines, 60.0)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30.0) == 0
        _wait_for(proc, "stopped:", lines, 5.0)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert all(line.startswith("<") for line in lines)  # journald priority prefixes
    assert (tmp_path / "ev.jsonl").exists()
