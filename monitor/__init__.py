"""Hydraulic fault monitor: DGRNN detection on CAN, a loop simulator and sim-to-real diagnosis."""

import time as _time

__version__ = "0.1.0"

#: time.monotonic() when the package was first imported: the process start, near enough, for
#: the daemon's start-up figure.
STARTED_MONO = _time.monotonic()
