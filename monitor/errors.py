"""One error root for the whole monitor.

Every user-facing failure is a ``MonitorError``; the CLI prints its message on one line
and exits with its ``exit_code``.  Children also subclass the builtin that fits, so a
library caller can catch ``ValueError`` or ``OSError`` as usual.
"""

from __future__ import annotations


class MonitorError(Exception):
    """Root of every error the monitor raises on purpose."""

    exit_code = 2


class ConfigError(MonitorError, ValueError):
    """A configuration file, a CLI argument or a parameter is wrong."""


class InputFileError(MonitorError, ValueError):
    """A recording, CSV, log or model file is malformed; the message names file and line."""


class NoHydraulicDataError(MonitorError, ValueError):
    """A recording is well formed but carries no usable hydraulic data."""

    exit_code = 3


class ModelFileError(MonitorError, ValueError):
    """A model file is corrupt, of another version or for other signals."""


class BusError(MonitorError, OSError):
    """The CAN bus could not be opened or used."""


class BusTimeoutError(MonitorError, TimeoutError):
    """Nothing arrived on the bus within the time allowed."""
