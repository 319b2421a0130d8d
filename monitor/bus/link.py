"""The bus link as the receive thread sees it: up, down or bus-off, error-passive or not;
the bus events it leaves for the event log; and the reopening of a failed bus with backoff
(the rules are in ``monitor.bus.recovery``).  Runs on the reader's thread
(``monitor.bus.reader``); only ``report_send_error`` comes from another one.
"""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable
from typing import Protocol

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

log = logging.getLogger("monitor.bus.reader")


class CanBus(Protocol):
    """What the monitor uses of a bus: a python-can ``BusABC``, or a wrapper with these
    methods (the live benchmark's bus that notes when each frame is taken off)."""

    def recv(self, timeout: float | None = None) -> can.Message | None: ...

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...

    def shutdown(self) -> None: ...


class Link:
    """``opener`` opens the bus again (None: a bus the caller owns, tried again as it is);
    ``sleep`` waits between attempts and returns True when the reader is stopping."""

    def __init__(
        self,
        opener: Callable[[], can.BusABC] | None,
        backoff: Backoff,
        sleep: Callable[[float], bool],
        clock: Callable[[], float],
    ) -> None:
        self.state = UP  # UP, DOWN or BUS_OFF
        self.error_passive = False
        self.recovery = RecoveryCounts()
        self.events: queue.SimpleQueue[BusEvent] = queue.SimpleQueue()
        self.opener = opener
        self.backoff = backoff
        self._sleep = sleep
        self._clock = clock
        self._reports: queue.SimpleQueue[str] = queue.SimpleQueue()  # from the sender
        self._down_since = 0.0
        self._proven = True  # a data frame came through since the last reopen

    @property
    def up(self) -> bool:
        return self.state == UP

    def report_send_error(self, exc: BaseException) -> None:
        """From the sending thread: a send failed.  A link error (ENETDOWN, ENODEV) may be
        the only report of the link going down, so the reader treats it as its own."""
        if is_link_error(exc):
            self._reports.put(f"send: {exc}")

    def take_report(self) -> str | None:
        """A link error the sender reported, if any."""
        try:
            return self._reports.get_nowait()
        except queue.Empty:
            return None

    def empty_receive(self) -> None:
        """A receive found nothing: on a reopened bus, it works (bus-off needs more)."""
        if self.state == DOWN:
            self._up("receive works again")

    def data_frame(self) -> None:
        """A data frame came through."""
        if self.state != UP:
            self._up("frames again")
        if not self._proven:  # the reopened bus carries traffic: next failure
            self._proven = True  # starts again from the initial delay
            self.backoff.reset()

    def error_frame(self, msg: can.Message, bus: CanBus) -> CanBus:
        """A controller error frame; the bus to go on with (reopened after a bus-off)."""
        kind = error_frame_kind(msg)
        if kind == "bus_off":
            return self.fail(BUS_OFF, "controller bus-off (error frame)", bus)
        if kind == "restarted":
            self.error_passive = False  # a restart clears the error counters
            if self.state == BUS_OFF:
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
        return bus

    def _event(self, kind: str, detail: str, down_s: float | None = None) -> None:
        self.events.put(BusEvent(kind, detail, time.time(), self.recovery.reopens, down_s))

    def fail(self, kind: str, detail: str, bus: CanBus) -> CanBus:
        """The bus failed (``kind`` DOWN or BUS_OFF): log it once, then reopen it; the bus to
        go on with."""
        if self.state == UP:
            if kind == DOWN:
                self.recovery.bus_down += 1
            else:
                self.recovery.bus_off += 1
            self._down_since = self._clock()
            self._event(kind, detail)
        else:  # the reopened bus failed before it worked: one more failed attempt
            self.recovery.reopen_failures += 1
        self.state = kind
        return self._reopen(detail, bus)

    def _reopen(self, detail: str, bus: CanBus) -> CanBus:
        while True:
            delay = self.backoff.next()
            self.recovery.reopen_attempts += 1
            log.warning(
                "CAN bus %s (%s); reopening in %.3g s",
                "off" if self.state == BUS_OFF else "down",
                detail,
                delay,
            )
            stopping = self._sleep(delay)
            # A send that failed before this outage was known reported it too: it is the
            # same outage (nothing is sent while the bus is down), not a new one.
            while self.take_report() is not None:
                pass
            if stopping or self.opener is None:
                return bus  # stopping, or a bus we cannot reopen: try it again as it is
            try:
                bus.shutdown()
            except (can.CanError, OSError) as exc:
                log.debug("closing the failed bus: %s", exc)
            try:
                bus = self.opener()
            except (can.CanError, OSError, ValueError) as exc:  # BusError is an OSError
                self.recovery.reopen_failures += 1
                detail = f"open: {exc}"
                continue
            self.recovery.reopens += 1
            self._proven = False
            log.info("CAN bus reopened (%d reopens so far)", self.recovery.reopens)
            return bus

    def _up(self, detail: str) -> None:
        down_s = self._clock() - self._down_since
        self.state = UP
        self._event("up", detail, down_s)
        log.info(
            "CAN bus up again after %.1f s (%s; %d reopens so far)",
            down_s,
            detail,
            self.recovery.reopens,
        )
