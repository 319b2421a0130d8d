"""Where the reference data lives: ../shared beside the checkout (absent in a user's clone)."""

from __future__ import annotations

from pathlib import Path

SHARED = Path(__file__).resolve().parents[2] / "shared"
REAL_LOGS = SHARED / "data" / "can-logs-real"
GOOD_LOGS = [
    "Yaris_09_steering.log",
    "camaro_candump-2021-04-18_191854.log",
    "durango_dooropen.log",
    "evox_only210.log",
    "forte_testlog.log",
    "genesis_candump-2021-05-28_164301.log",
]
# file, line number of the first malformed line (found by reading the files)
BAD_LOGS = [("civic8th_test.log", 1)]
# file, line number of its torn last line (cut off mid-line, no newline): read up to it
TORN_LOGS = [("evox_linklog2.log", 1096)]
