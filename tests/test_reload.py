"""SIGHUP in the field: a reload never clears an alarm by itself, and parsing the new
config never stalls detection.

The spool-wear log raises one fault at 55.61 s that lasts to its end (``monitor detect``).
A reload at 80 s, with the same model and settings, must leave the events exactly as
``monitor detect`` gives them; with changed alarm settings (a new ticker) the alarm state
must hold through the new J window and go on: still one fault, never a ``normal`` between.
"""

from __future__ import annotations

import threading
from pathlib import Path

import can
import pytest
from live_support import assert_same_events, settle, wait_until, write_config

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.io.candump import read_candump
from monitor.live import reload as reload_module
from monitor.live.daemon import Daemon
from monitor.model.modelfile import load_model
from monitor.resources import resource_path
from monitor.sampling.read import read_recording

LOG = resource_path("replay", "spool_wear.log")
RELOAD_AT_S = 80.0  # bus seconds after the first frame: inside the fault


def _config(tmp_path: Path, clear_samples: int = 300) -> Path:
    return write_config(
        tmp_path,
        f"bus: {{interface: virtual, channel: reload-{tmp_path.name}, queue_frames: 200000,"
        " silent_s: 30}\n"
        f"event_log: {{path: {tmp_path / 'ev.jsonl'}}}\n"
        f"black_box: {{directory: {tmp_path / 'bb'}}}\n"
        f"alarm: {{clear_samples: {clear_samples}}}\n",
    )


def _run_with_reload(
    tmp_path: Path, clear_samples: int | None
) -> tuple[Daemon, list[dict], list[str]]:
    """Replay the log onto a daemon, reloading (after rewriting the config with
    ``clear_samples``, if given) once the frames before RELOAD_AT_S are processed."""
    cfg_path = _config(tmp_path)
    cfg = load_config(cfg_path)
    msgs = list(read_candump(LOG))
    cut = next(i for i, m in enumerate(msgs) if m.timestamp - msgs[0].timestamp >= RELOAD_AT_S)
    events: list[dict] = []
    states_at_reload: list[str] = []
    daemon = Daemon(cfg, on_event=events.append)
    with can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True) as tx:
        daemon.start()
        try:
            for m in msgs[:cut]:
                tx.send(m)
            settle(daemon, cut)
            states_at_reload.append(daemon.state.label)
            if clear_samples is not None:
                _config(tmp_path, clear_samples)
            daemon.request_reload()
            wait_until(lambda: daemon.reload_attempts == 1)
            for m in msgs[cut:]:
                tx.send(m)
            settle(daemon, len(msgs))
        finally:
            daemon.stop()
    assert daemon.error is None and daemon.reloads == 1
    return daemon, events, states_at_reload


def _offline() -> list[dict]:
    cfg = load_config()
    return detect(
        load_model(cfg.model), read_recording(LOG), cfg.alarm, cfg.horizon, gating=cfg.gating
    ).events


def test_reload_with_the_same_model_changes_no_event(tmp_path, caplog) -> None:
    caplog.set_level("INFO", logger="monitor")
    daemon, events, at_reload = _run_with_reload(tmp_path, None)
    assert at_reload == ["fault"]
    assert_same_events(events, _offline())
    assert "unchanged; its J window and alarm state go on" in caplog.text


def test_reload_with_new_settings_holds_the_alarm_through_the_new_window(tmp_path) -> None:
    daemon, events, at_reload = _run_with_reload(tmp_path, 400)
    assert at_reload == ["fault"]
    assert daemon.cfg.alarm.clear_samples == 400  # the new settings took effect
    offline = _offline()
    assert [(e["t"], e["state"]) for e in events] == [(e["t"], e["state"]) for e in offline]
    assert daemon.state.label == "fault" and len(list((tmp_path / "bb").glob("*.log"))) == 1


def test_a_slow_reload_never_stalls_detection(tmp_path, monkeypatch) -> None:
    """While the config is being parsed (held here until released), frames go on being
    decoded and ticked; the reload lands when the parse ends."""
    cfg = load_config(_config(tmp_path))
    release = threading.Event()
    real = reload_module.load_config

    def slow_load(source):  # noqa: ANN001, ANN202
        release.wait(120)
        return real(source)

    monkeypatch.setattr(reload_module, "load_config", slow_load)
    msgs = list(read_candump(LOG))[:6000]
    daemon = Daemon(cfg)
    with can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True) as tx:
        daemon.start()
        try:
            daemon.request_reload()
            for m in msgs:
                tx.send(m)
            settle(daemon, len(msgs))
            ticks = daemon.loops[0].ticker.ticks
            assert ticks > 1000 and daemon.reload_attempts == 0  # ticked while parsing
            release.set()
            wait_until(lambda: daemon.reload_attempts == 1)
        finally:
            release.set()
            daemon.stop()
    assert daemon.reloads == 1 and daemon.error is None


@pytest.mark.parametrize("bad", ["alarm: [1, 2\n", "a: &x [1]\nb: *x\n", "model: /nonexistent\n"])
def test_a_bad_reload_keeps_everything_running(tmp_path, bad: str, caplog) -> None:
    cfg_path = _config(tmp_path)
    daemon = Daemon(load_config(cfg_path))
    daemon.start()
    try:
        cfg_path.write_text(cfg_path.read_text() + bad)
        daemon.request_reload()
        wait_until(lambda: daemon.reload_attempts == 1)
    finally:
        daemon.stop()
    assert daemon.reloads == 0 and daemon.error is None
    assert "reload failed, keeping the running config and model" in caplog.text


def test_a_reload_that_takes_too_long_is_given_up_and_its_late_result_dropped(
    monkeypatch,
) -> None:
    from monitor.live.reload import Reloader

    monkeypatch.setattr(reload_module, "RELOAD_LIMIT_S", -1.0)  # every parse is overdue
    release, finished = threading.Event(), threading.Event()

    def slow() -> Exception:
        release.wait(120)
        finished.set()
        return ValueError("the late result")

    r = Reloader(slow)
    r.request()
    given_up = r.poll()
    assert isinstance(given_up, TimeoutError) and "given up" in str(given_up)
    assert r.poll() is None  # given up once, not at every poll
    release.set()
    assert finished.wait(120)
    wait_until(lambda: not r.busy)
    assert r.poll() is None and not r.pending  # the late result is dropped
