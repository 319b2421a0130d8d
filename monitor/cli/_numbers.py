"""Command-line numbers checked while the command line is parsed (argparse ``type=``): a
non-number, NaN, infinity or a value outside the option's range is exit 2 naming the
option, before any work (``--duration 1e9`` would otherwise ask for 745 GiB)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def _text(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else f"{v:g}"


def number(
    lo: float, hi: float, *, whole: bool = False, unit: str = "", why: str = ""
) -> Callable[[str], float]:
    """An argparse type: a finite number within ``lo..hi`` (``whole``: an int); ``why``, if
    given, says in the message why the range ends where it does."""
    what = "a whole number" if whole else "a number"
    span = f"{_text(lo)}..{_text(hi)}{' ' + unit if unit else ''}"

    def parse(text: str) -> float:
        try:
            value = float(text) if len(text) <= 40 else math.nan
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or (whole and not value.is_integer()):
            raise argparse.ArgumentTypeError(f"must be {what} within {span}, got {text[:40]!r}")
        if not lo <= value <= hi:
            because = f" ({why})" if why else ""
            raise argparse.ArgumentTypeError(f"must be within {span}, got {text[:40]}{because}")
        return int(value) if whole else value

    parse.__name__ = "whole number" if whole else "number"  # argparse names it on errors
    return parse


#: Longest simulation (s): the simulator holds the whole run in memory, some 0.3 GB a
#: simulated hour (7,200 s peaked at 0.84 GB RSS; 6 h at 2.29 GB).
DURATION_MAX_S = 7_200.0
DURATION_WHY = (
    "the run is held in memory, some 0.3 GB a simulated hour; simulate longer "
    "spans as several runs with other seeds"
)
SEED_MAX = 2**32 - 1  # numpy's SeedSequence takes any non-negative int; keep it printable
WINDOW_MAX = 360_000  # one hour of 100 Hz samples
EPOCH_MAX_S = 4_102_444_800.0  # 2100-01-01: a candump timestamp beyond is not a recording
