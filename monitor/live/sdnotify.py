"""The systemd notification protocol (sd_notify(3)), for ``Type=notify`` services.

The service manager passes ``NOTIFY_SOCKET`` (a unix datagram socket; a leading ``@`` means
the abstract namespace) and, with ``WatchdogSec=``, ``WATCHDOG_USEC`` (and
``WATCHDOG_PID``).  Without ``NOTIFY_SOCKET`` every call is a no-op, so the daemon runs the
same from a shell.  A message that cannot be sent is logged once and otherwise ignored:
the monitor must not stop because the service manager went away.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Mapping

log = logging.getLogger(__name__)


class Notifier:
    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        path = env.get("NOTIFY_SOCKET", "")
        self.address: str | bytes | None = None
        if path.startswith("@"):
            self.address = b"\0" + path[1:].encode()
        elif path.startswith("/"):
            self.address = path
        self.watchdog_s = self._watchdog(env)
        self._sock: socket.socket | None = None
        self._warned = False

    @staticmethod
    def _watchdog(env: Mapping[str, str]) -> float | None:
        """The watchdog timeout (s) when it is meant for this process, else None."""
        pid = env.get("WATCHDOG_PID")
        if pid is not None and pid.strip() != str(os.getpid()):
            return None
        try:
            usec = int(env.get("WATCHDOG_USEC", "0"))
        except ValueError:
            return None
        return usec / 1e6 if usec > 0 else None

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def notify(self, *fields: str, **named: str | int) -> bool:
        """Send ``KEY=value`` lines as one datagram; True when sent."""
        if self.address is None:
            return False
        text = "\n".join([*fields, *(f"{k}={v}" for k, v in named.items())])
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(text.encode(), self.address)
        except OSError as exc:
            if not self._warned:
                self._warned = True
                log.warning("cannot notify the service manager at %r: %s", self.address, exc)
            return False
        return True

    def ready(self, status: str = "") -> bool:
        return self.notify("READY=1", *([f"STATUS={status}"] if status else []))

    def reloading(self) -> bool:
        # MONOTONIC_USEC lets systemd (Type=notify-reload, v253+) tell this reload apart.
        usec = time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000
        return self.notify("RELOADING=1", MONOTONIC_USEC=usec)

    def stopping(self) -> bool:
        return self.notify("STOPPING=1")

    def watchdog(self) -> bool:
        return self.notify("WATCHDOG=1")

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
