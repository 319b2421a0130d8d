"""systemd's notify protocol: ``monitor run`` as a process, a unix datagram socket bound
as NOTIFY_SOCKET in the test, the messages checked in order (what systemd would see)."""

from __future__ import annotations

import os
import signal
import socket
import time

import pytest
from live_support import start_daemon, wait_for_text, write_config

from monitor.live.sdnotify import Notifier

pytestmark = pytest.mark.skipif(not hasattr(socket, "AF_UNIX"), reason="unix sockets")


def _messages(sock: socket.socket, until: str, got: list[dict[str, str]], timeout_s: float):
    """Receive datagrams into ``got`` (one dict per message) until one has key ``until``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        sock.settimeout(max(0.01, end - time.monotonic()))
        try:
            data = sock.recv(4096).decode()
        except TimeoutError:
            break
        msg = dict(line.split("=", 1) for line in data.splitlines())
        got.append(msg)
        if until in msg:
            return
    raise AssertionError(f"no {until} from the daemon; got {got}")


def test_run_notifies_ready_watchdog_reload_and_stopping(tmp_path) -> None:
    cfg = write_config(
        tmp_path,
        "bus:\n  interface: virtual\n  channel: sdnotify\n"
        f"event_log:\n  path: {tmp_path / 'ev.jsonl'}\n"
        f"black_box:\n  directory: {tmp_path / 'bb'}\n",
    )
    sock_path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(sock_path))
    log = tmp_path / "daemon.log"
    env = {"NOTIFY_SOCKET": str(sock_path), "WATCHDOG_USEC": "400000"}
    proc = start_daemon(cfg, tmp_path, log, env)
    got: list[dict[str, str]] = []
    try:
        _messages(sock, "READY", got, 120.0)
        _messages(sock, "WATCHDOG", got, 10.0)
        _messages(sock, "WATCHDOG", got, 10.0)  # pings keep coming (every 0.2 s)
        before_us = time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000
        proc.send_signal(signal.SIGHUP)
        _messages(sock, "RELOADING", got, 30.0)
        after_us = time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000
        _messages(sock, "READY", got, 60.0)
        wait_for_text(log, "reloaded", proc, 10.0)
        proc.send_signal(signal.SIGTERM)
        _messages(sock, "STOPPING", got, 30.0)
        assert proc.wait(30.0) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        sock.close()
    order = [next(iter(m)) for m in got if "WATCHDOG" not in m]
    assert order == ["READY", "RELOADING", "READY", "STOPPING"], got
    assert sum("WATCHDOG" in m for m in got) >= 2
    assert got[0]["READY"] == "1" and got[0]["STATUS"] == "monitoring virtual:sdnotify"
    reloading = next(m for m in got if "RELOADING" in m)
    # MONOTONIC_USEC is CLOCK_MONOTONIC, which this process shares with the daemon.
    assert before_us <= int(reloading["MONOTONIC_USEC"]) <= after_us


def test_without_notify_socket_nothing_is_sent() -> None:
    n = Notifier({})
    assert not n.enabled and n.watchdog_s is None
    assert n.ready() is False and n.watchdog() is False and n.stopping() is False


def test_abstract_socket_and_watchdog_for_this_process_only(tmp_path) -> None:
    name = f"monitor-test-{os.getpid()}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(b"\0" + name.encode())
    sock.settimeout(5.0)
    try:
        n = Notifier(
            {
                "NOTIFY_SOCKET": "@" + name,
                "WATCHDOG_USEC": "3000000",
                "WATCHDOG_PID": str(os.getpid()),
            }
        )
        assert n.watchdog_s == 3.0
        assert n.watchdog()
        assert sock.recv(100) == b"WATCHDOG=1"
        n.close()
    finally:
        sock.close()
    other = Notifier({"NOTIFY_SOCKET": "/x", "WATCHDOG_USEC": "3000000", "WATCHDOG_PID": "1"})
    assert other.watchdog_s is None  # the watchdog belongs to another process


def test_a_vanished_service_manager_is_not_fatal(tmp_path) -> None:
    n = Notifier({"NOTIFY_SOCKET": str(tmp_path / "gone.sock")})
    assert n.enabled
    assert n.ready() is False  # logged once, the daemon goes on
