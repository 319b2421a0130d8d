"""Helpers for the SocketCAN tests (tests/test_vcan_*.py): a kernel ``vcan0`` with can-utils
as independent peers and ``monitor run`` as a process of its own.

The guest VM of CI runs Python 25-40x slower than the host, so logs go on the bus
``SLOWER`` times slower than real time (``MONITOR_VCAN_SLOWDOWN``, 1 on a real Linux box)
and the daemon runs with ``bus.time_scale`` = ``SLOWER``: its sample clock, events and
expected times stay in log seconds.
"""

from __future__ import annotations

import functools
import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import can
import cantools
from live_support import sigint_default

from monitor.io.candump import format_line, read_candump
from monitor.resources import resource_path

CHANNEL = "vcan0"
SLOWER = float(os.environ.get("MONITOR_VCAN_SLOWDOWN", "1"))
CAN_UTILS = ("candump", "canplayer", "cansend", "cangen")
DBC = cantools.database.load_file(str(resource_path("dbc", "monitor.dbc")))


def vcan_missing() -> str | None:
    """Why the vcan tests cannot run here, or None.  With ``MONITOR_VCAN_REQUIRED=1`` (the
    CI VM) a reason is an error, so a broken VM cannot pass as skipped tests."""
    reason = _vcan_missing()
    if reason and os.environ.get("MONITOR_VCAN_REQUIRED") == "1":
        raise RuntimeError(f"MONITOR_VCAN_REQUIRED=1 but {reason}")
    return reason


def _vcan_missing() -> str | None:
    if not hasattr(socket, "AF_CAN"):
        return "no SocketCAN in this Python/OS"
    if not Path(f"/sys/class/net/{CHANNEL}").exists():
        return (
            f"no {CHANNEL} (ip link add dev {CHANNEL} type vcan && ip link set {CHANNEL} "
            "up; or .ci/vm/run-in-vm.sh)"
        )
    missing = [t for t in CAN_UTILS if shutil.which(t) is None]
    if missing:
        return f"can-utils missing: {', '.join(missing)} (apt install can-utils)"
    return None


def vcan_config(tmp: Path, model: Path, bus_extra: str = "") -> str:
    """YAML for the daemon on vcan0, outputs under ``tmp``; ``bus_extra``: more lines of
    the bus section."""
    bus = (
        f"bus:\n  interface: socketcan\n  channel: {CHANNEL}\n  time_scale: {SLOWER}\n"
        "  queue_frames: 200000\n  silent_s: 4.0\n"
    )
    outputs = (
        f"event_log:\n  path: {tmp / 'events.jsonl'}\nblack_box:\n  directory: {tmp / 'blackbox'}\n"
    )
    # The small vcan model (tests/vcan_model.sh: two runs, each at one oil temperature) has a
    # training envelope that leaves out the shipped logs' 56-58 degC: gated, nothing would be
    # judged.  These tests are about the bus path; the gating has its own tests
    # (tests/test_gating.py), so here out-of-range samples are only counted.
    validity = "validity:\n  gate: false\n"
    return bus + bus_extra + outputs + validity


@functools.lru_cache(maxsize=8)
def log_frames(src: Path, t_to: float = float("inf")) -> tuple[can.Message, ...]:
    """The frames of a time-ordered log up to log time ``t_to``, read once (parsing is slow
    in the VM)."""
    out: list[can.Message] = []
    for m in read_candump(src):
        if out and m.timestamp - out[0].timestamp >= t_to:
            break
        out.append(m)
    return tuple(out)


def slowed_copy(
    src: Path,
    dst: Path,
    t_from: float = 0.0,
    t_to: float = float("inf"),
    drop_id_after: tuple[int, float] | None = None,
    slower: float = SLOWER,
) -> list[can.Message]:
    """Write the frames of ``src`` with log time in [t_from, t_to) to ``dst`` for canplayer
    on vcan0, ``slower`` times slower; ``drop_id_after`` = (frame id, log time) leaves that
    frame out from then on.  Returns the frames kept (with their original timestamps)."""
    frames = log_frames(src, t_to)
    t0 = frames[0].timestamp
    kept = []
    with dst.open("w") as fh:
        for m in frames:
            t = m.timestamp - t0
            if t >= t_to:
                break  # the shipped logs are in time order
            if t < t_from:
                continue
            if drop_id_after and m.arbitration_id == drop_id_after[0] and t >= drop_id_after[1]:
                continue
            ts = t0 + t_from + (t - t_from) * slower
            fh.write(format_line(ts, CHANNEL, m.arbitration_id, m.is_extended_id, m.data))
            kept.append(m)
    return kept


class Capture:
    """``candump -L vcan0`` into a file, line-buffered so it can be read while it runs;
    stopped with SIGINT."""

    def __init__(self, path: Path) -> None:
        self.path = path
        with path.open("wb") as out:
            self.proc = subprocess.Popen(
                ["stdbuf", "-oL", "candump", "-L", CHANNEL],
                stdout=out,
                preexec_fn=sigint_default,  # stopped by SIGINT even if the suite ignores it
            )

    def snapshot(self) -> list[can.Message]:
        """The frames captured so far (complete lines only)."""
        text = self.path.read_text()
        snap = self.path.with_suffix(".snapshot")
        snap.write_text(text[: text.rfind("\n") + 1])
        return list(read_candump(snap))

    def stop(self) -> list[can.Message]:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            self.proc.wait(30)
        return list(read_candump(self.path))

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()


def decode(msgs: list[can.Message], name: str) -> list[tuple[float, dict]]:
    """(timestamp, signals) of every ``name`` frame, decoded by cantools from the DBC."""
    frame_id = DBC.get_message_by_name(name).frame_id
    return [
        (m.timestamp, DBC.decode_message(frame_id, m.data, decode_choices=False))
        for m in msgs
        if m.arbitration_id == frame_id
    ]


def frame_id(name: str) -> int:
    return DBC.get_message_by_name(name).frame_id


def stop(proc: subprocess.Popen, timeout_s: float = 120.0) -> int:
    """SIGTERM and wait for the exit status."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    return proc.wait(timeout_s)


class Phases:
    """Wall time of each phase of a session, printed (pytest -s shows it) and kept."""

    def __init__(self) -> None:
        self.last = time.monotonic()
        self.took: dict[str, float] = {}

    def __call__(self, name: str) -> None:
        now = time.monotonic()
        self.took[name] = now - self.last
        self.last = now
        print(f"[vcan] {name}: {self.took[name]:.1f} s wall", flush=True)
