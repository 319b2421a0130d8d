"""The bus side: opening a python-can bus for the monitor, and the receive thread.

The receive thread does one thing: move frames from the bus into a bounded queue, counting
them (and when the bus fails, open it again: monitor/bus_recovery.py).  Decoding, sampling
and detection run on the daemon's own thread, so a slow tick can never block reception; if
that thread falls behind long enough for the queue to fill, the newest frames are dropped
and counted (the sampler then sees stale data, a sensor fault), never lost silently.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from monitor.bus.link import CanBus, Link
from monitor.bus.recovery import DOWN, Backoff, BusEvent, RecoveryCounts
from monitor.errors import BusError, ConfigError
from monitor.schema.sections import setting

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BusConfig:
    """The CAN bus: any python-can interface (``socketcan`` on the controller, ``virtual``
    in tests and the demo)."""

    interface: str = setting("socketcan", doc="any python-can interface")
    channel: str = setting("can0", doc="the CAN channel (can0, vcan0, a multicast group...)")
    bitrate: int = setting(
        500_000,
        check=lambda v: 10_000 <= v <= 1_000_000,
        demand="between 10000 and 1000000",
        unit="bit/s",
    )
    # Bounded receive buffer (~5 s of a full 500 kbit/s bus); overflow is counted as dropped.
    queue_frames: int = setting(20_000, check=lambda v: v >= 100, demand=">= 100", unit="frames")
    kernel_filters: bool = setting(True, doc="only the DBC's sensor IDs reach user space")
    # No frame this long: the sample clock runs on, rows go stale (proven silence only).
    silent_s: float = setting(0.5, unit="s")
    # Bus seconds per sample-clock second: 4 when a log is replayed 4x slower than real time
    # onto the bus (a slow test bench or emulator); event times then read in log seconds.
    time_scale: float = setting(1.0, unit="bus s per sample s")
    # Extra keyword arguments for can.Bus (e.g. fd, receive_own_messages); scalars only.
    options: dict[str, Any] = setting(factory=dict)
    # A bus that fails (link down, bus-off) is reopened after a delay that starts here and
    # doubles per failed attempt up to reopen_max_s (monitor/bus/recovery.py).
    reopen_initial_s: float = setting(
        0.1, check=lambda v: 0.001 <= v <= 3600, demand="between 0.001 and 3600", unit="s"
    )
    reopen_max_s: float = setting(
        10.0, check=lambda v: 0.001 <= v <= 3600, demand="between 0.001 and 3600", unit="s"
    )

    def __post_init__(self) -> None:
        # The sampler keeps a signal fresh for 3 of its cycles.  A bus whose frames come at
        # their DBC cycle time, read on a clock k times faster (k = time_scale < 1), sees
        # them 1/k cycles apart: below k = 0.5 that is past 2 cycles, and every jitter makes
        # rows stale (a monitor flapping inactive).  Above 100 a 10 ms row is 1 s of bus.
        if not TIME_SCALE_MIN <= self.time_scale <= TIME_SCALE_MAX:
            raise ConfigError(
                f"bus.time_scale must be within {TIME_SCALE_MIN:g}..{TIME_SCALE_MAX:g} (bus "
                f"seconds per sample-clock second), got {self.time_scale:g}: the sampler "
                "cannot honour a faster clock (frames would go stale between rows)"
            )
        if not 0.0 < self.silent_s <= 60.0:
            raise ConfigError(f"bus.silent_s must be within 0..60 s, got {self.silent_s:g}")


TIME_SCALE_MIN = 0.5
TIME_SCALE_MAX = 100.0


def open_bus(cfg: BusConfig, can_filters: list[dict[str, int | bool]] | None = None) -> can.BusABC:
    """A thread-safe python-can bus (send and receive from different threads).

    With ``can_filters`` and ``cfg.kernel_filters`` only those IDs are received (in the
    kernel on socketcan): the daemon passes the DBC's sensor IDs plus J1939 requests.  On the
    ``virtual`` interface the sender's timestamps are kept, so a log replayed at any speed
    keeps its own clock, as it does from a file.
    Controller error frames (bus-off, error-passive) reach the reader on socketcan:
    python-can sets CAN_RAW_ERR_FILTER to every error class unless the option
    ``ignore_rx_error_frames`` is given, and CAN_RAW_FILTER (the ID filters) does not
    apply to them (checked on vcan0 in the CI VM).
    """
    kwargs: dict[str, Any] = {"interface": cfg.interface, "channel": cfg.channel}
    if cfg.interface != "virtual":
        kwargs["bitrate"] = cfg.bitrate
    else:
        kwargs["preserve_timestamps"] = True
    if can_filters is not None and cfg.kernel_filters:
        kwargs["can_filters"] = list(can_filters)
    kwargs.update(cfg.options)
    try:
        bus = can.ThreadSafeBus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise BusError(
            f"cannot open CAN bus {cfg.interface}:{cfg.channel}: {exc}"
            + (
                f" (is the interface up? {_bring_up_hint(cfg.channel, cfg.bitrate)})"
                if cfg.interface == "socketcan"
                else ""
            )
        ) from None
    got = enlarge_receive_buffer(bus)
    if got is not None:
        log.debug("%s:%s receive buffer %d bytes", cfg.interface, cfg.channel, got)
    return bus


#: Kernel receive buffer asked for the bus socket: a few seconds of a busy bus.  The default
#: (~200 kB, a few hundred frames) overflows while a busy controller keeps the reader thread
#: off the CPU for a fraction of a second, and the kernel drops frames nobody counts.
RCVBUF_BYTES = 4 << 20
_SO_RCVBUFFORCE = 33  # Linux: beyond net.core.rmem_max, for a privileged daemon


def enlarge_receive_buffer(bus: can.BusABC, size: int = RCVBUF_BYTES) -> int | None:
    """Ask for a ``size``-byte receive buffer on the bus's socket (socketcan,
    udp_multicast); the size the kernel granted, or None for a bus without a socket."""
    sock = getattr(bus, "socket", None)
    if not isinstance(sock, socket.socket):  # udp_multicast keeps it one level down
        sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if not isinstance(sock, socket.socket):
        return None
    for opt in (_SO_RCVBUFFORCE, socket.SO_RCVBUF):  # unprivileged: up to net.core.rmem_max
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, size)
            break
        except OSError:
            continue
    return int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))


@dataclass
class ReaderCounts:
    received: int = 0  # frames taken off the bus
    dropped: int = 0  # frames lost because the queue was full
    bus_errors: int = 0  # exceptions from recv (the thread keeps going)
    error_frames: int = 0  # CAN error frames reported by the controller


class BusReader:
    """Receive thread: bus -> bounded queue of ``can.Message``; reopens a failed bus.

    With ``opener`` (a function that opens the bus again) a link failure or bus-off closes
    the bus and opens a new one after a backoff delay (monitor/bus_recovery.py); without
    one (a bus the caller owns) the same bus is tried again after the delay.  The thread
    never ends on a bus error; it ends on ``stop``.  Bus events (down, up, bus-off,
    error-passive) wait in ``events`` for the detector thread, which logs them.  The link's
    state and its recovery are the reader's ``link`` (``monitor.bus.link``).
    ``sleep`` (returns True when stopping) and ``clock`` are injectable for tests.
    """

    def __init__(
        self,
        bus: CanBus,
        queue_frames: int,
        poll_s: float = 0.05,
        opener: Callable[[], can.BusABC] | None = None,
        backoff: Backoff | None = None,
        sleep: Callable[[float], bool] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.bus: CanBus = bus
        self.queue: queue.Queue[can.Message] = queue.Queue(maxsize=queue_frames)
        self.counts = ReaderCounts()
        self.poll_s = poll_s
        self._stop = threading.Event()
        self.link = Link(opener, backoff or Backoff(0.1, 10.0), sleep or self._stop.wait, clock)
        self._clock = clock
        self._thread = threading.Thread(target=self._run, name="can-reader", daemon=True)
        self._last_drop_log = 0.0
        self._heard_until = -float("inf")
        self._received_at = -float("inf")

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    @property
    def heard_until(self) -> float:
        """Monotonic time up to which every received frame is in the queue: the start of the
        latest receive that found nothing, or now while the bus is down or bus-off (nothing
        can arrive).  Silence is proven by this, never by a thread that merely got no CPU
        for a while (see monitor.live.pipeline)."""
        return self._clock() if not self.link.up else self._heard_until

    @property
    def received_at(self) -> float:
        """Monotonic time at which this thread received its latest frame (stamped on receive,
        before the queue): the start of any silence the reader can prove."""
        return self._received_at

    @property
    def bus_up(self) -> bool:
        """Whether sending can work: the bus is neither down nor bus-off."""
        return self.link.up

    @property
    def recovery(self) -> RecoveryCounts:
        return self.link.recovery

    @property
    def opener(self) -> Callable[[], can.BusABC] | None:
        return self.link.opener

    @property
    def error_passive(self) -> bool:
        return self.link.error_passive

    @property
    def events(self) -> queue.SimpleQueue[BusEvent]:
        """Bus events (down, up, bus-off, error-passive) waiting for the detector thread."""
        return self.link.events

    def report_send_error(self, exc: BaseException) -> None:
        """From the sending thread: a send failed (``Link.report_send_error``)."""
        self.link.report_send_error(exc)

    def take_events(self) -> list[BusEvent]:
        return _drain(self.link.events)

    def _run(self) -> None:
        link = self.link
        while not self._stop.is_set():
            report = link.take_report()
            if report is not None:
                self.bus = link.fail(DOWN, report, self.bus)
                continue
            asked = self._clock()
            try:
                msg = self.bus.recv(timeout=self.poll_s)
            except (can.CanError, OSError, ValueError) as exc:
                self.counts.bus_errors += 1
                self.bus = link.fail(DOWN, f"receive: {exc}", self.bus)
                continue
            if msg is None:
                self._heard_until = asked
                link.empty_receive()
                continue
            self._received_at = self._clock()
            self._put(msg)
            if msg.is_error_frame:
                self.counts.error_frames += 1
                self.bus = link.error_frame(msg, self.bus)
            else:
                link.data_frame()

    def _put(self, msg: can.Message) -> None:
        """Queue a received frame, or count it dropped (the queue is full)."""
        self.counts.received += 1
        try:
            self.queue.put_nowait(msg)
        except queue.Full:
            self.counts.dropped += 1
            now = time.monotonic()
            if now - self._last_drop_log > 5.0:  # a flood must not flood the journal too
                self._last_drop_log = now
                log.warning("receive queue full: %d frames dropped so far", self.counts.dropped)


def _bring_up_hint(channel: str, bitrate: int) -> str:
    """The command that brings ``channel`` up: a vcan needs the module and no bitrate."""
    if channel.startswith("vcan"):
        return (
            f"`sudo modprobe vcan && sudo ip link add dev {channel} type vcan && "
            f"sudo ip link set {channel} up`"
        )
    return f"`sudo ip link set {channel} up type can bitrate {bitrate}`"


def _drain(q: queue.Queue[Any] | queue.SimpleQueue[Any]) -> list:
    """Everything queued right now, without waiting."""
    out = []
    while True:
        try:
            out.append(q.get_nowait())
        except queue.Empty:
            return out
