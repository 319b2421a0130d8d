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
from typing import Any, Protocol

import can

from monitor.bus.recovery import (
    BUS_OFF,
    DOWN,
    UP,
    Backoff,
    BusEvent,
    RecoveryCounts,
    error_frame_kind,
    is_link_error,
)
from monitor.errors import BusError, ConfigError
from monitor.schema.sections import setting

log = logging.getLogger(__name__)


class CanBus(Protocol):
    """What the monitor uses of a bus: a python-can ``BusABC``, or a wrapper with these
    methods (the live benchmark's bus that notes when each frame is taken off)."""

    def recv(self, timeout: float | None = None) -> can.Message | None: ...

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...

    def shutdown(self) -> None: ...


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
    error-passive) wait in ``events`` for the detector thread, which logs them.
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
        self.recovery = RecoveryCounts()
        self.link = UP  # UP, DOWN or BUS_OFF
        self.error_passive = False
        self.events: queue.SimpleQueue[BusEvent] = queue.SimpleQueue()
        self.poll_s = poll_s
        self.opener = opener
        self.backoff = backoff or Backoff(0.1, 10.0)
        self._stop = threading.Event()
        self._sleep = sleep or self._stop.wait
        self._clock = clock
        self._reports: queue.SimpleQueue[str] = queue.SimpleQueue()  # from the sender
        self._down_since = 0.0
        self._proven = True  # a data frame came through since the last reopen
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
        return self._clock() if self.link != UP else self._heard_until

    @property
    def received_at(self) -> float:
        """Monotonic time at which this thread received its latest frame (stamped on receive,
        before the queue): the start of any silence the reader can prove."""
        return self._received_at

    @property
    def bus_up(self) -> bool:
        """Whether sending can work: the bus is neither down nor bus-off."""
        return self.link == UP

    def report_send_error(self, exc: BaseException) -> None:
        """From the sending thread: a send failed.  A link error (ENETDOWN, ENODEV) may be
        the only report of the link going down, so the reader treats it as its own."""
        if is_link_error(exc):
            self._reports.put(f"send: {exc}")

    def take_events(self) -> list[BusEvent]:
        return _drain(self.events)

    def _run(self) -> None:
        counts, put = self.counts, self.queue.put_nowait
        while not self._stop.is_set():
            try:
                report = self._reports.get_nowait()
            except queue.Empty:
                pass
            else:
                self._fail(DOWN, report)
                continue
            asked = self._clock()
            try:
                msg = self.bus.recv(timeout=self.poll_s)
            except (can.CanError, OSError, ValueError) as exc:
                counts.bus_errors += 1
                self._fail(DOWN, f"receive: {exc}")
                continue
            if msg is None:
                self._heard_until = asked
                if self.link == DOWN:  # the reopened bus works (bus-off needs more)
                    self._up("receive works again")
                continue
            self._received_at = self._clock()
            counts.received += 1
            try:
                put(msg)
            except queue.Full:
                counts.dropped += 1
                now = time.monotonic()
                if now - self._last_drop_log > 5.0:  # a flood must not flood the journal too
                    self._last_drop_log = now
                    log.warning("receive queue full: %d frames dropped so far", counts.dropped)
            if msg.is_error_frame:
                counts.error_frames += 1
                self._error_frame(msg)
            else:
                if self.link != UP:
                    self._up("frames again")
                if not self._proven:  # the reopened bus carries traffic: next failure
                    self._proven = True  # starts again from the initial delay
                    self.backoff.reset()

    def _error_frame(self, msg: can.Message) -> None:
        kind = error_frame_kind(msg)
        if kind == "bus_off":
            self._fail(BUS_OFF, "controller bus-off (error frame)")
        elif kind == "restarted":
            self.error_passive = False  # a restart clears the error counters
            if self.link == BUS_OFF:
                self._up("controller restarted")
        elif kind == "error_passive" and not self.error_passive:
            self.error_passive = True
            self.recovery.error_passive += 1
            self._event("error_passive", f"controller error-passive (status 0x{msg.data[1]:02X})")
            log.warning("CAN controller error-passive (status 0x%02X)", msg.data[1])
        elif kind == "error_active" and self.error_passive:
            self.error_passive = False
            self._event("error_active", "controller back to error-active")
            log.info("CAN controller back to error-active")

    def _event(self, kind: str, detail: str, down_s: float | None = None) -> None:
        self.events.put(BusEvent(kind, detail, time.time(), self.recovery.reopens, down_s))

    def _fail(self, kind: str, detail: str) -> None:
        """The bus failed (``kind`` DOWN or BUS_OFF): log it once, then reopen it."""
        if self.link == UP:
            if kind == DOWN:
                self.recovery.bus_down += 1
            else:
                self.recovery.bus_off += 1
            self._down_since = self._clock()
            self._event(kind, detail)
        else:  # the reopened bus failed before it worked: one more failed attempt
            self.recovery.reopen_failures += 1
        self.link = kind
        self._reopen(detail)

    def _reopen(self, detail: str) -> None:
        while True:
            delay = self.backoff.next()
            self.recovery.reopen_attempts += 1
            log.warning(
                "CAN bus %s (%s); reopening in %.3g s",
                "off" if self.link == BUS_OFF else "down",
                detail,
                delay,
            )
            stopping = self._sleep(delay)
            # A send that failed before this outage was known reported it too: it is the
            # same outage (nothing is sent while the bus is down), not a new one.
            _drain(self._reports)
            if stopping or self.opener is None:
                return  # stopping, or a bus we cannot reopen: try it again as it is
            try:
                self.bus.shutdown()
            except (can.CanError, OSError) as exc:
                log.debug("closing the failed bus: %s", exc)
            try:
                self.bus = self.opener()
            except (can.CanError, OSError, ValueError) as exc:  # BusError is an OSError
                self.recovery.reopen_failures += 1
                detail = f"open: {exc}"
                continue
            self.recovery.reopens += 1
            self._proven = False
            log.info("CAN bus reopened (%d reopens so far)", self.recovery.reopens)
            return

    def _up(self, detail: str) -> None:
        down_s = self._clock() - self._down_since
        self.link = UP
        self._event("up", detail, down_s)
        log.info(
            "CAN bus up again after %.1f s (%s; %d reopens so far)",
            down_s,
            detail,
            self.recovery.reopens,
        )


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
