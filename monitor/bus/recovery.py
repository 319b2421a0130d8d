"""What the receive thread does when the bus fails, and the record it leaves.

Three kinds of trouble, as a SocketCAN controller reports them (``linux/can/error.h``):

* the link fails: ``recv`` raises (python-can's ``CanOperationError`` wrapping the OSError;
  on SocketCAN errno ENETDOWN after ``ip link set can0 down``, ENODEV when the interface
  is removed), or a send fails with such an errno.  The kernel reports a link going down
  once per socket, to whichever call comes first, so the sending thread passes its link
  errors on (``BusReader.report_send_error``);
* the controller goes bus-off: an error frame with ``CAN_ERR_BUSOFF`` in its id;
* the controller goes error-passive: an error frame with ``CAN_ERR_CRTL`` and
  ``CAN_ERR_CRTL_RX_PASSIVE``/``TX_PASSIVE`` in data[1].  Frames still flow there (the
  node only stops sending active error flags), so it is counted and logged, with the way
  back (``CAN_ERR_CRTL_ACTIVE``), and nothing is reopened.

A link failure or bus-off closes the bus and opens it again (on the receive thread) after
a delay that starts at ``bus.reopen_initial_s`` and doubles up to ``bus.reopen_max_s`` while
attempts fail: an open that raises, or a reopened bus that fails again before it has carried
a frame.  SocketCAN lets a socket bind to an interface that is down and reports ENETDOWN on
its first ``recv``, so a reopen succeeds only once the link is up again.  The bus counts as
up again when a ``recv`` on the reopened bus returns without error (after bus-off: when a
data frame or the controller's restart is seen); the delay goes back to the initial one
once a data frame has come through.  Reopening a SocketCAN socket does not restart a
bus-off controller: set ``restart-ms`` on the interface (``ip link set can0 type can
bitrate 500000 restart-ms 100``) and the kernel restarts it; on interfaces whose driver
opens the controller with the bus (PCAN, Kvaser, ...) the reopen itself restarts it.

The detector is not told to forget anything: a gap in the frames is a gap in the sample
clock as for any silence (stale rows, state inactive, the J window paused, see
monitor/live/daemon.py), so the daemon gives the events ``monitor detect`` gives for a log with
the same gap, and a fault that was on before the outage is raised again within the
debounce after it, not after a fresh window.
"""

from __future__ import annotations

import errno
from dataclasses import asdict, dataclass

import can

# linux/can/error.h: error class bits in the id of an error frame, and data[1] of CRTL.
CAN_ERR_CRTL = 0x004
CAN_ERR_BUSOFF = 0x040
CAN_ERR_RESTARTED = 0x100
CAN_ERR_CRTL_RX_PASSIVE = 0x10
CAN_ERR_CRTL_TX_PASSIVE = 0x20
CAN_ERR_CRTL_ACTIVE = 0x40

#: errnos that mean the link itself is gone (not a full transmit queue, ENOBUFS).
LINK_ERRNOS = frozenset({errno.ENETDOWN, errno.ENODEV, errno.ENXIO})

# Link states of the reader.
UP, DOWN, BUS_OFF = "up", "down", "bus_off"


def error_frame_kind(msg: can.Message) -> str | None:
    """What a controller error frame says about the bus: ``"bus_off"``, ``"restarted"``,
    ``"error_passive"``, ``"error_active"``, or None (bus errors, warnings, lost
    arbitration, ...: counted, nothing to do)."""
    cls = msg.arbitration_id
    if cls & CAN_ERR_BUSOFF:
        return "bus_off"
    if cls & CAN_ERR_RESTARTED:
        return "restarted"
    if cls & CAN_ERR_CRTL and len(msg.data) > 1:
        status = msg.data[1]
        if status & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE):
            return "error_passive"
        if status & CAN_ERR_CRTL_ACTIVE:
            return "error_active"
    return None


def link_errno(exc: BaseException) -> int | None:
    """The errno behind a python-can or OS error (``CanOperationError.error_code``)."""
    code = getattr(exc, "error_code", None)
    if code is None:
        code = getattr(exc, "errno", None)
    return code if isinstance(code, int) else None


def is_link_error(exc: BaseException) -> bool:
    return link_errno(exc) in LINK_ERRNOS


class Backoff:
    """Delays before reopening: ``initial_s``, doubled per failed attempt, at most ``max_s``."""

    def __init__(self, initial_s: float, max_s: float) -> None:
        if not 0 < initial_s <= max_s:
            raise ValueError(f"backoff needs 0 < initial ({initial_s}) <= max ({max_s})")
        self.initial_s = float(initial_s)
        self.max_s = float(max_s)
        self._next = self.initial_s

    def next(self) -> float:
        delay = self._next
        self._next = min(self._next * 2.0, self.max_s)
        return delay

    def reset(self) -> None:
        self._next = self.initial_s


@dataclass
class RecoveryCounts:
    bus_down: int = 0  # link failures (recv or send reported the link gone)
    bus_off: int = 0  # bus-off reported by the controller
    error_passive: int = 0  # entries into error-passive
    reopen_attempts: int = 0  # delays waited before a reopen
    reopens: int = 0  # buses opened again
    reopen_failures: int = 0  # opens that raised, reopened buses that failed again at once

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


@dataclass(frozen=True)
class BusEvent:
    """One change of the bus's state, as the receive thread saw it."""

    kind: str  # "down", "up", "bus_off", "error_passive", "error_active"
    detail: str  # the error text, or how the bus came back
    wall_s: float  # time.time() when seen
    reopens: int  # buses opened again so far (this run)
    down_s: float | None = None  # for "up": how long the bus was down or bus-off
