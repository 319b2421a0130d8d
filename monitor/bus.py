"""The bus side: opening a python-can bus for the monitor, and the receive thread.

The receive thread does one thing: move frames from the bus into a bounded queue, counting
them.  Decoding, sampling and detection run on the daemon's own thread, so a slow tick can
never block reception; if that thread falls behind long enough for the queue to fill, the
newest frames are dropped and counted (the sampler then sees stale data, a sensor fault),
never lost silently.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from dataclasses import dataclass

import can

from monitor.codec.frames import FrameCodec
from monitor.config import BusConfig
from monitor.errors import BusError
from monitor.sampler import hydraulic_messages

log = logging.getLogger(__name__)

_ID_MASK_EXT = 0x1FFFFFFF
_ID_MASK_STD = 0x7FF


def sensor_filters(codec: FrameCodec) -> list[dict[str, int | bool]]:
    """python-can filters passing exactly the DBC's sensor frames (not our own MON_*)."""
    out: list[dict[str, int | bool]] = []
    for name in sorted(hydraulic_messages(codec)):
        info = codec.messages[name]
        mask = _ID_MASK_EXT if info.is_extended_id else _ID_MASK_STD
        out.append({"can_id": info.frame_id, "can_mask": mask, "extended": info.is_extended_id})
    return out


def open_bus(cfg: BusConfig, codec: FrameCodec | None = None) -> can.BusABC:
    """A thread-safe python-can bus (send and receive from different threads).

    With ``codec`` and ``cfg.kernel_filters`` only the DBC's sensor IDs are received
    (in the kernel on socketcan).  On the ``virtual`` interface the sender's timestamps are
    kept, so a log replayed at any speed keeps its own clock, as it does from a file.
    """
    kwargs: dict[str, object] = {"interface": cfg.interface, "channel": cfg.channel}
    if cfg.interface != "virtual":
        kwargs["bitrate"] = cfg.bitrate
    else:
        kwargs["preserve_timestamps"] = True
    if codec is not None and cfg.kernel_filters:
        kwargs["can_filters"] = sensor_filters(codec)
    kwargs.update(cfg.options)
    try:
        return can.ThreadSafeBus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise BusError(
            f"cannot open CAN bus {cfg.interface}:{cfg.channel}: {exc}"
            + (
                " (is the interface up? `ip link set can0 up type can bitrate 500000`)"
                if cfg.interface == "socketcan"
                else ""
            )
        ) from None


@dataclass
class ReaderCounts:
    received: int = 0  # frames taken off the bus
    dropped: int = 0  # frames lost because the queue was full
    bus_errors: int = 0  # exceptions from recv (the thread keeps going)
    error_frames: int = 0  # CAN error frames reported by the controller


class BusReader:
    """Receive thread: bus -> bounded queue of ``can.Message``."""

    def __init__(self, bus: can.BusABC, queue_frames: int, poll_s: float = 0.05) -> None:
        self.bus = bus
        self.queue: queue.Queue[can.Message] = queue.Queue(maxsize=queue_frames)
        self.counts = ReaderCounts()
        self.poll_s = poll_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-reader", daemon=True)
        self._last_drop_log = 0.0

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        counts, put = self.counts, self.queue.put_nowait
        while not self._stop.is_set():
            try:
                msg = self.bus.recv(timeout=self.poll_s)
            except (can.CanError, OSError, ValueError) as exc:
                counts.bus_errors += 1
                log.error("bus receive failed (%s); retrying", exc)
                self._stop.wait(0.5)  # a bus that fails at once must not spin the CPU
                continue
            if msg is None:
                continue
            counts.received += 1
            if msg.is_error_frame:
                counts.error_frames += 1
            try:
                put(msg)
            except queue.Full:
                counts.dropped += 1
                now = time.monotonic()
                if now - self._last_drop_log > 5.0:  # a flood must not flood the journal too
                    self._last_drop_log = now
                    log.warning("receive queue full: %d frames dropped so far", counts.dropped)
