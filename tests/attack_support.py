"""The attack harness: ``monitor run``, a replayer and a sniffer, each a process of its own,
on a udp_multicast group and port of their own (the field's shape: the sensor ECUs, the
controller and a service laptop are different machines).

``AttackRig`` starts the daemon on a config it writes, replays candump logs with
``monitor replay``, records every frame on the bus with python-can's own logger
(``python -m can.logger``), and kills or stops the daemon the way an attacker or a power
cut would (SIGKILL) or the service manager does (SIGTERM).  What it reads back: the event
lines of every event-log file (current and rotated), the frames the sniffer saw.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import can
from live_support import REPO, own_udp_port, sigint_default, start_daemon, wait_for_text

from monitor.live.storage import rotated_logs

_groups = iter(range(40, 250))


def multicast_error() -> str | None:
    """Why udp_multicast cannot run here (None: it can)."""
    try:
        bus = can.Bus(interface="udp_multicast", channel="239.74.164.1", port=own_udp_port())
        bus.shutdown()
    except Exception as exc:  # noqa: BLE001 - any failure means: not on this host
        return f"python-can udp_multicast unavailable here: {exc}"
    return None


class AttackRig:
    """One attack's bus (group, port) and the daemon's folder ``root``; ``event_log``: more
    keys of that section (``rotate_mb: 0.001``), ``extra``: more YAML (``storage: ...``)."""

    def __init__(
        self, root: Path, event_log: str = "", extra: str = "", time_scale: float = 0.5
    ) -> None:
        self.root = root
        self.group = f"239.74.165.{next(_groups)}"
        self.port = own_udp_port()
        self.env = {
            **os.environ,
            "PYTHONPATH": str(REPO),
            "CAN_CONFIG": json.dumps({"port": self.port}),
        }
        self.config = root / "attack.yaml"
        self.config.write_text(
            f'bus: {{interface: udp_multicast, channel: "{self.group}", time_scale: '
            f"{time_scale}}}\nevent_log: {{path: events.jsonl{', ' if event_log else ''}"
            f"{event_log}}}\n"
            # The shipped logs are the reference machine's, as is the shipped model.
            f"black_box: {{directory: blackbox}}\nmachine_id: reference\n{extra}"
        )
        self.events_path = root / "events.jsonl"
        self.daemon: subprocess.Popen | None = None
        self.sniffer: subprocess.Popen | None = None
        self.starts = 0

    # -- the daemon -----------------------------------------------------------------------

    def start(self) -> subprocess.Popen:
        """``monitor run`` on the rig's config; returns once it is monitoring."""
        self.starts += 1
        log = self.root / f"daemon-{self.starts}.log"
        self.daemon = start_daemon(self.config, self.root, log, env=self.env)
        wait_for_text(log, "monitoring", self.daemon, 180.0)
        return self.daemon

    def kill(self) -> None:
        """SIGKILL: no ordered stop, as a power cut or the OOM killer."""
        assert self.daemon is not None
        self.daemon.kill()
        self.daemon.wait(60)

    def stop(self) -> int:
        """SIGTERM: the ordered stop; the exit code."""
        assert self.daemon is not None
        self.daemon.send_signal(signal.SIGTERM)
        return self.daemon.wait(120)

    # -- the other machines ---------------------------------------------------------------

    def replay(self, log: Path, speed: float = 2.0) -> None:
        """``monitor replay`` of ``log`` from a process of its own, to its end."""
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "monitor",
                "replay",
                str(log),
                "--bus",
                self.group,
                "--interface",
                "udp_multicast",
                "--speed",
                str(speed),
            ],
            capture_output=True,
            text=True,
            env=self.env,
            timeout=1800,
            check=False,
        )
        assert r.returncode == 0, r.stderr

    def sniff(self) -> None:
        """Record every frame on the bus from now on (python-can's logger, a process of its
        own; the frames of the first moment, before it joined the group, may be missed)."""
        out = self.root / "sniffed.log"
        self.sniffer = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "can.logger",
                "-i",
                "udp_multicast",
                "-c",
                self.group,
                "-f",
                str(out),
                "--bus-kwargs",
                f"port={self.port}",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            env=self.env,
            # SIGINT stops it: a suite started in the background of a shell without job
            # control inherits SIGINT ignored, and so would the logger (it hung there).
            preexec_fn=sigint_default,
        )

    def sniffed(self) -> list[can.Message]:
        """Stop the sniffer (SIGINT: it closes its file) and read what it saw."""
        assert self.sniffer is not None
        if self.sniffer.poll() is not None:  # it died: say why
            raise AssertionError(self.sniffer.stderr.read() if self.sniffer.stderr else "")
        self.sniffer.send_signal(signal.SIGINT)
        self.sniffer.wait(60)
        return list(can.LogReader(self.root / "sniffed.log"))

    # -- what is on the disk --------------------------------------------------------------

    def event_files(self) -> list[Path]:
        """The event log's files, oldest first."""
        return [*rotated_logs(self.events_path), self.events_path]

    def events(self) -> list[dict[str, Any]]:
        """Every event line of the event log's files, oldest first (each whole JSON)."""
        return [
            json.loads(x)
            for p in self.event_files()
            if p.exists()
            for x in p.read_text().splitlines()
            if x.strip()
        ]

    def _events_so_far(self) -> list[dict[str, Any]]:
        """``events`` while the daemon writes: a line being appended is skipped."""
        out = []
        for p in self.event_files():
            for x in p.read_text().splitlines() if p.exists() else []:
                try:
                    out.append(json.loads(x))
                except ValueError:
                    continue
        return out

    def wait_event(self, cond: Any, timeout_s: float = 180.0) -> dict[str, Any]:
        """The first event line for which ``cond`` holds, once the daemon wrote it (bounded:
        a hang detector, not a timing)."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for e in self._events_so_far():
                if cond(e):
                    return e
            if self.daemon is not None and self.daemon.poll() is not None:
                break
            time.sleep(0.2)
        raise AssertionError(f"no such event; the log holds {self._events_so_far()[-5:]}")
